//! Device → TOML text, laid out like a hand-written device file.

use std::fmt::Write as _;

use super::serde_helpers::convention_name;
use super::{Device, JointRef};

/// The device file text of `device` (docs/design.md §5); [`parse_device`](crate::parse_device)
/// reads it back to an equal [`Device`].
///
/// Numbers are written in Rust's shortest form that parses back to the same `f64`
/// (at most 17 significant digits), so nothing is lost in the round trip.
pub fn write_device(device: &Device) -> String {
    let mut out = String::new();
    let mut line = |text: String| {
        out.push_str(&text);
        out.push('\n');
    };
    line("# hapcal device file (docs/design.md §5); lengths in m, angles in rad".into());
    if let Some(name) = &device.name {
        line(format!("name = {}", string(name)));
    }
    if !device.dh.is_empty() {
        line(format!(
            "convention = {}",
            string(convention_name(device.convention))
        ));
    }
    for row in &device.dh {
        line(String::new());
        line("[[dh]]".into());
        line(format!("a_m = {}", float(row.a_m)));
        line(format!("alpha_rad = {}", float(row.alpha_rad)));
        line(format!("d_m = {}", float(row.d_m)));
        line(format!("theta_rad = {}", float(row.theta_rad)));
        if let Some(beta) = row.beta_rad {
            line(format!("beta_rad = {}", float(beta)));
        }
        line(match row.joint {
            JointRef::Joint(j) => format!("joint = {j}"),
            JointRef::Fixed => "joint = \"fixed\"".into(),
        });
    }
    if let Some(urdf) = &device.urdf {
        line(String::new());
        line("[urdf]".into());
        line(format!("path = {}", string(&urdf.path.to_string_lossy())));
        line(format!("tip = {}", string(&urdf.tip)));
    }
    for p in &device.placements {
        line(String::new());
        line("[[placement]]".into());
        placement(&mut line, p);
    }
    for b in &device.branches {
        line(String::new());
        line("[[branch]]".into());
        if let Some(from) = &b.from {
            line(format!("from = {}", string(from)));
        }
        for p in &b.placements {
            line(String::new());
            line("[[branch.placement]]".into());
            placement(&mut line, p);
        }
    }
    let prismatic = device.prismatic_joints();
    for (k, j) in device.joints.iter().enumerate() {
        line(String::new());
        line("[[joint]]".into());
        line(format!("name = {}", string(&j.name)));
        // A prismatic joint's limits are lengths.
        let unit = if prismatic.get(k) == Some(&true) {
            "m"
        } else {
            "rad"
        };
        line(format!("lower_{unit} = {}", float(j.lower_rad)));
        line(format!("upper_{unit} = {}", float(j.upper_rad)));
        if let Some(counts) = j.counts_per_rev {
            line(format!("counts_per_rev = {counts}"));
        }
    }
    for c in &device.capstans {
        line(String::new());
        line("[[capstan]]".into());
        line(format!("joint = {}", c.joint));
        line(format!("ratio = {}", float(c.ratio)));
        line(format!("drum_distance_m = {}", float(c.drum_distance_m)));
    }
    if let Some(p) = &device.parallelogram {
        line(String::new());
        line("[parallelogram]".into());
        line(format!("l1_m = {}", float(p.l1_m)));
        line(format!("l2_m = {}", float(p.l2_m)));
        line(format!("l3_m = {}", float(p.l3_m)));
        line(format!("l4_m = {}", float(p.l4_m)));
    }
    if let Some(c) = &device.cable_encoder {
        line(String::new());
        line("[cable_encoder]".into());
        line(format!("drum_radius_m = {}", float(c.drum_radius_m)));
        line(format!("counts_per_rev = {}", c.counts_per_rev));
    }
    if let Some(h) = &device.handle {
        line(String::new());
        line("[handle]".into());
        line(format!("mass_kg = {}", float(h.mass_kg)));
    }
    if let Some(c) = &device.calibration {
        // The contract's writer: the same keys and number forms as a URDF's sidecar.
        c.write_toml(Some("calibration"), &mut out);
    }
    out
}

/// The keys of one placement row.
fn placement(line: &mut impl FnMut(String), p: &hapcal_kinematics::Placement) {
    line(format!("name = {}", string(&p.name)));
    line(format!("xyz_m = {}", array(&p.xyz_m)));
    line(format!("rpy_rad = {}", array(&p.rpy_rad)));
    if let Some(axis) = p.axis {
        line(format!("axis = {}", array(&axis)));
        if p.prismatic {
            line("prismatic = true".into());
        }
    }
}

/// A TOML float that parses back to exactly `v`.
pub(crate) fn float(v: f64) -> String {
    if v.is_nan() {
        "nan".into()
    } else if v.is_infinite() {
        if v > 0.0 { "inf".into() } else { "-inf".into() }
    } else {
        // Debug is the shortest round-trip form and always has a `.` or an exponent.
        format!("{v:?}")
    }
}

fn array(values: &[f64]) -> String {
    let items: Vec<String> = values.iter().map(|v| float(*v)).collect();
    format!("[{}]", items.join(", "))
}

/// A TOML basic string.
fn string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\t' => out.push_str("\\t"),
            '\r' => out.push_str("\\r"),
            c if c.is_control() => {
                let _ = write!(out, "\\u{:04X}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}
