//! Writing a record as TOML: every number in full precision (Rust's shortest round-trip
//! form), so that a reader recovers the written values bit for bit.

use std::fmt::Write;

use crate::Calibration;

/// A TOML string literal.
fn string(s: &str) -> String {
    toml::Value::String(s.to_owned()).to_string()
}

/// A key: bare when it can be, quoted otherwise.
fn key(k: &str) -> String {
    let bare = !k.is_empty()
        && k.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-');
    if bare { k.to_owned() } else { string(k) }
}

/// A float in its shortest round-trip form (always with a `.` or an exponent).
fn float(x: f64) -> String {
    format!("{x:?}")
}

fn array(xs: &[f64]) -> String {
    let items: Vec<String> = xs.iter().map(|x| float(*x)).collect();
    format!("[{}]", items.join(", "))
}

impl Calibration {
    /// The record as a sidecar file (`robot.calibration.toml`), its keys at the top level.
    pub fn to_sidecar_toml(&self) -> String {
        let mut s = String::from(
            "# The calibration record of `hapcal calibrate` (docs/design.md §5.6): what the robot \
             description cannot hold.\n",
        );
        self.write_toml(None, &mut s);
        s
    }

    /// Writes the record into `out` as TOML: under the table `table` (`Some("calibration")`
    /// in a device file: `[calibration]`, `[calibration.values]`, …) or at the top level.
    pub fn write_toml(&self, table: Option<&str>, out: &mut String) {
        let prefix = table.map_or(String::new(), |t| format!("{t}."));
        if let Some(t) = table {
            let _ = writeln!(out, "\n[{t}]");
        }
        if let Some(v) = self.schema_version {
            let _ = writeln!(out, "schema_version = {v}");
        }
        if let Some(m) = self.model {
            let _ = writeln!(out, "model = {}", string(m.name()));
        }
        for (k, v) in [
            ("date", &self.date),
            ("data_hash", &self.data_hash),
            ("notes", &self.notes),
        ] {
            if let Some(v) = v {
                let _ = writeln!(out, "{k} = {}", string(v));
            }
        }
        if !self.tips.is_empty() {
            let tips: Vec<String> = self.tips.iter().map(|t| string(t)).collect();
            let _ = writeln!(out, "tips = [{}]", tips.join(", "));
        }
        if let Some(d) = &self.urdf_digest {
            let _ = writeln!(out, "urdf_digest = {}", string(d));
        }
        if let Some(t) = &self.torque {
            let _ = writeln!(out, "\n[{prefix}torque]");
            let _ = writeln!(out, "source = {}", string(t.source.as_str()));
            let _ = writeln!(out, "gravity_direction = {}", array(&t.gravity_direction));
            let _ = writeln!(out, "gravity_m_s2 = {}", float(t.gravity_m_s2));
            let _ = writeln!(out, "equilibrium = {}", t.equilibrium);
            let tips: Vec<String> = t.tips.iter().map(|t| string(t)).collect();
            let _ = writeln!(out, "tips = [{}]", tips.join(", "));
            if let Some(m) = t.handle_mass_kg {
                let _ = writeln!(out, "handle_mass_kg = {}", float(m));
            }
            for m in &t.masses {
                let _ = writeln!(out, "\n[[{prefix}torque.mass]]");
                let _ = writeln!(out, "joint = {}", string(&m.joint));
                let _ = writeln!(out, "mass_kg = {}", float(m.mass_kg));
                let _ = writeln!(out, "com_m = {}", array(&m.com_m));
            }
        }
        if let Some(r) = &self.region {
            let _ = writeln!(out, "\n[{prefix}region]");
            let _ = writeln!(out, "rows = {}", r.rows);
            for j in &r.joints {
                let _ = writeln!(out, "\n[[{prefix}region.joint]]");
                let _ = writeln!(out, "name = {}", string(&j.name));
                let _ = writeln!(out, "min = {}", float(j.min));
                let _ = writeln!(out, "max = {}", float(j.max));
                let _ = writeln!(out, "unit = {}", string(&j.unit));
            }
        }
        for (table, frames) in [("frames", &self.frames), ("nominal", &self.nominal)] {
            for (name, f) in frames {
                let _ = writeln!(out, "\n[{prefix}{table}.{}]", key(name));
                let _ = writeln!(out, "xyz_m = {}", array(&f.xyz_m));
                let _ = writeln!(out, "rpy_rad = {}", array(&f.rpy_rad));
            }
        }
        if !self.values.is_empty() {
            let _ = writeln!(out, "\n[{prefix}values]");
            for v in &self.values {
                let _ = writeln!(
                    out,
                    "{} = {{ value = {}, std = {}, unit = {} }}",
                    key(&v.name),
                    float(v.value),
                    float(v.std),
                    string(&v.unit)
                );
            }
        }
        if let Some(c) = &self.covariance {
            let _ = writeln!(out, "\n[{prefix}covariance]");
            let names: Vec<String> = c.names.iter().map(|n| string(n)).collect();
            let _ = writeln!(out, "names = [{}]", names.join(", "));
            // One row of the lower triangle a line.
            let _ = writeln!(out, "lower = [");
            let mut k = 0;
            for i in 0..c.names.len() {
                let row = &c.lower[k..k + i + 1];
                k += i + 1;
                let items: Vec<String> = row.iter().map(|x| float(*x)).collect();
                let _ = writeln!(out, "  {},", items.join(", "));
            }
            let _ = writeln!(out, "]");
        }
    }
}
