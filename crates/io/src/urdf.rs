//! URDF import (a device from a URDF joint chain) and write-back of calibrated joint origins.

use std::collections::HashMap;
use std::ops::Range;
use std::path::Path;
use std::sync::{Arc, Mutex};

use hapcal_kinematics::Placement;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use quick_xml::XmlVersion;
use quick_xml::events::{BytesStart, Event};
use quick_xml::reader::Reader;

use hapcal_contract::urdf;
use hapcal_contract::urdf::MAX_XML_DEPTH;

use crate::Error;
use crate::device::{Branch, Device, JointSpec, UrdfSource};
use crate::error::line_column;

/// A device whose chain is the URDF's joints from the root link to the link `tip`.
///
/// The chain is found by walking from `tip` to its parent link until a link without a
/// parent joint (the root). Each joint becomes a [`Placement`] (its `<origin xyz rpy>`;
/// its `<axis>` for revolute, continuous and prismatic joints, none for fixed ones) and each
/// moving joint a `[[joint]]` entry named after it, with the URDF's `<limit lower upper>`
/// (rad; m for a prismatic joint) and [−π, π] for a continuous joint (hapcal needs finite
/// limits to check and sample joint readings; widen them in the device file if the joint
/// turns further). `[urdf]` records `path` (as given) and `tip`, for
/// [`write_calibrated_urdf`]. Transmissions, rig and handle are left empty.
///
/// # Errors
///
/// [`Error::Io`] if the file cannot be read; [`Error::Xml`] (file:line:column) for
/// malformed XML; [`Error::UrdfStructure`] (file:line:column of the joint or link) if a
/// joint names an undefined link, a link has two parent joints, several links have none or
/// the joints form a loop, or the chain to `tip` is longer than [`MAX_CHAIN_LENGTH_M`]
/// (lengths in mm); [`Error::Urdf`] if urdf-rs cannot parse it, the chain has no moving joint,
/// or a number is not finite or a revolute or prismatic joint lacks finite `lower < upper`
/// limits; [`Error::TipNotFound`] (listing every link) if there is no link `tip`;
/// [`Error::UnsupportedJoint`] for a floating or planar joint on the chain.
pub fn import_urdf(path: &Path, tip: &str) -> Result<Device, Error> {
    let robot = read_robot(path)?;
    let chain = chain_to(&robot, tip, path)?;
    check_chain_length(&chain, tip, path)?;
    let mut placements = Vec::with_capacity(chain.len());
    let mut joints = Vec::new();
    for joint in &chain {
        let (placement, spec) = placement_of(joint, path, Limits::Continuous1Turn)?;
        placements.push(placement);
        joints.extend(spec);
    }
    if joints.is_empty() {
        let root = chain.first().map_or(tip, |j| j.parent.link.as_str());
        return Err(urdf_error(
            path,
            format!("no moving joint between the root link {root:?} and {tip:?}"),
        ));
    }

    let device = Device {
        name: Some(robot.name.clone()),
        convention: hapcal_kinematics::DhConvention::Standard,
        dh: Vec::new(),
        urdf: Some(UrdfSource {
            path: path.to_path_buf(),
            tip: tip.to_owned(),
        }),
        placements,
        branches: Vec::new(),
        joints,
        capstans: Vec::new(),
        parallelogram: None,
        cable_encoder: None,
        handle: None,
        calibration: None,
    };
    device.chain()?;
    Ok(device)
}

/// A device whose placements form a tree with the links `tips` as its tips: the path to
/// the first tip as in [`import_urdf`], and each further tip as a [`Branch`] hanging from the
/// last joint its path shares with the paths before it (from the root link if it shares
/// none), with the `[[joint]]` entries of its own moving joints after the earlier ones (the
/// joint order of [`import_urdf_tips`]). Limits as in [`import_urdf`]. With one tip, the
/// device of [`import_urdf`].
///
/// # Errors
///
/// As [`import_urdf_tips`].
pub fn import_urdf_tree(path: &Path, tips: &[String]) -> Result<Device, Error> {
    let Some((first, rest)) = tips.split_first() else {
        return Err(urdf_error(path, "no tip link given".into()));
    };
    let mut device = import_urdf(path, first)?;
    if rest.is_empty() {
        return Ok(device);
    }
    // The checks of a tree: tips named once, under one root.
    import_urdf_tips(path, tips)?;
    let robot = read_robot(path)?;
    let mut known: Vec<String> = device.placements.iter().map(|p| p.name.clone()).collect();
    for tip in rest {
        let chain = chain_to(&robot, tip, path)?;
        // In a tree the joints above a link are one path: the known ones are a prefix.
        let shared = chain.iter().take_while(|j| known.contains(&j.name)).count();
        let from = (shared.checked_sub(1))
            .and_then(|i| chain.get(i))
            .map(|j| j.name.clone());
        let mut placements = Vec::new();
        for joint in chain.iter().skip(shared) {
            let (placement, spec) = placement_of(joint, path, Limits::Continuous1Turn)?;
            device.joints.extend(spec);
            known.push(placement.name.clone());
            placements.push(placement);
        }
        device.branches.push(Branch { from, placements });
    }
    device.tree()?;
    Ok(device)
}

/// A URDF robot with one or more tips: the root-to-tip paths, the moving joints and the
/// links' masses ([`import_urdf_tips`]).
#[derive(Clone, Debug, PartialEq)]
pub struct UrdfTree {
    /// One root-to-tip path of placements per tip, in the order the tips were asked for
    /// (shared joints appear on each path that passes through them).
    pub paths: Vec<Vec<Placement>>,
    /// The moving joints in order of first appearance, path by path (the joint numbering of
    /// `hapcal_kinematics::Tree::from_placement_paths`); limits in rad, m for prismatic
    /// joints.
    pub joints: Vec<JointSpec>,
    /// Whether each joint of `joints` is prismatic.
    pub prismatic: Vec<bool>,
    /// The `<inertial>` of every link with a mass below a moving joint of the paths, on the
    /// paths or off them (another arm, a head, a tool below a tip), in the frame of the
    /// nearest such joint above it.
    pub inertials: Vec<LinkInertial>,
    /// The moving joints off the paths that [`UrdfTree::inertials`] hold at their zero
    /// position (between a link with a mass and the nearest joint of the paths above it: a
    /// head's pan and tilt), in file order without repeats.
    pub held_joints: Vec<String>,
}

/// A link's `<inertial>` mass and centre of mass, expressed in the frame of the nearest
/// moving joint above it (the frame just after that joint's motion).
#[derive(Clone, Debug, PartialEq)]
pub struct LinkInertial {
    /// Index of that joint in [`UrdfTree::joints`] (0-based).
    pub joint: usize,
    /// The link's name.
    pub link: String,
    /// Mass, kg (≥ 0).
    pub mass_kg: f64,
    /// Centre of mass in the joint's frame, m (through the fixed joints between them).
    pub com_m: [f64; 3],
}

/// The URDF's robot as a tree with the links `tips` as tips: several arms on one torso,
/// several markers on one hand. Joint limits as in [`import_urdf`], except that a continuous
/// joint gets ±1000 rad (a readout of a continuous joint may have turned many times).
///
/// # Errors
///
/// As [`import_urdf`], per tip; [`Error::Urdf`] without tips, for a tip named twice, for
/// tips under different root links, for a link mass or centre of mass that is not finite or
/// a negative mass.
pub fn import_urdf_tips(path: &Path, tips: &[String]) -> Result<UrdfTree, Error> {
    let robot = read_robot(path)?;
    if tips.is_empty() {
        return Err(urdf_error(path, "no tip link given".into()));
    }
    let mut chains = Vec::with_capacity(tips.len());
    for (i, tip) in tips.iter().enumerate() {
        if tips[..i].contains(tip) {
            return Err(urdf_error(path, format!("tip link {tip:?} is given twice")));
        }
        let chain = chain_to(&robot, tip, path)?;
        check_chain_length(&chain, tip, path)?;
        chains.push(chain);
    }
    let root_of = |chain: &[&urdf::Joint], tip: &str| {
        chain
            .first()
            .map_or(tip.to_owned(), |j| j.parent.link.clone())
    };
    let root = root_of(&chains[0], &tips[0]);
    for (chain, tip) in chains.iter().zip(tips).skip(1) {
        let other = root_of(chain, tip);
        if other != root {
            return Err(urdf_error(
                path,
                format!(
                    "tip {tip:?} hangs from the root link {other:?}, tip {:?} from {root:?}: the tips must share one root",
                    tips[0]
                ),
            ));
        }
    }
    let mut paths = Vec::with_capacity(chains.len());
    let mut joints: Vec<JointSpec> = Vec::new();
    let mut prismatic = Vec::new();
    for chain in &chains {
        let mut placements = Vec::with_capacity(chain.len());
        for joint in chain {
            let (placement, spec) = placement_of(joint, path, Limits::Continuous1000)?;
            if let Some(spec) = spec
                && !joints.iter().any(|j| j.name == spec.name)
            {
                prismatic.push(placement.prismatic);
                joints.push(spec);
            }
            placements.push(placement);
        }
        paths.push(placements);
    }
    if joints.is_empty() {
        return Err(urdf_error(
            path,
            format!("no moving joint between the root link {root:?} and the tips"),
        ));
    }
    let (inertials, held_joints) = inertials(&robot, &joints, path)?;
    Ok(UrdfTree {
        paths,
        joints,
        prismatic,
        inertials,
        held_joints,
    })
}

/// The links to add to `tips` as further tips so that the moving joints of `read` (the joint
/// columns a measurement file holds) that hang off the root-to-tip paths and carry a link
/// mass onto them ([`UrdfTree::held_joints`]) lie on a path: their readings then load the
/// gravity torques as they were read, instead of being held at zero. A further tip is the
/// deepest link reached from the paths through moving joints of `read` alone (and fixed
/// joints), the one covering the most such joints first; in file order of the held joints,
/// without repeats. Empty when no held joint is read.
///
/// # Errors
/// As [`import_urdf_tips`].
pub fn load_tips(path: &Path, tips: &[String], read: &[String]) -> Result<Vec<String>, Error> {
    let tree = import_urdf_tips(path, tips)?;
    let wanted: Vec<&String> = (tree.held_joints.iter())
        .filter(|j| read.contains(j))
        .collect();
    if wanted.is_empty() {
        return Ok(Vec::new());
    }
    let robot = read_robot(path)?;
    let on_paths = |joint: &urdf::Joint| tree.joints.iter().any(|j| j.name == joint.name);
    // Per link: the moving joints between it and the paths, if each is read (else `None`:
    // the link cannot be a tip whose every joint has a reading; or the walk met the root,
    // never meeting a path).
    let reach = |link: &str| -> Option<Vec<String>> {
        let walk = urdf::walk_up(&robot, link, on_paths);
        walk.stop?;
        let mut off = Vec::new();
        for joint in walk.passed {
            if !matches!(joint.joint_type, urdf::JointType::Fixed) {
                if !read.contains(&joint.name) {
                    return None;
                }
                off.push(joint.name.clone());
            }
        }
        Some(off)
    };
    let candidates: Vec<(String, Vec<String>)> = (robot.links.iter())
        .filter(|l| !tips.contains(&l.name))
        .filter_map(|l| reach(&l.name).map(|off| (l.name.clone(), off)))
        .filter(|(_, off)| !off.is_empty())
        .collect();
    let mut added: Vec<String> = Vec::new();
    let mut covered: Vec<String> = Vec::new();
    for joint in wanted {
        if covered.contains(joint) {
            continue;
        }
        let best = (candidates.iter())
            .filter(|(_, off)| off.contains(joint))
            .max_by_key(|(_, off)| off.iter().filter(|j| !covered.contains(j)).count());
        if let Some((link, off)) = best {
            added.push(link.clone());
            covered.extend(off.iter().cloned());
        }
    }
    Ok(added)
}

/// The inertial of every link of the robot that hangs below one of `joints` (the moving
/// joints on the measured paths), expressed in the frame of the nearest such joint above it.
///
/// Links off the measured paths count too: the other arm of a torso when only one hand is
/// measured, a head, a tool below the tip link. The joints between such a link and the
/// nearest measured joint are taken at their zero position (a moving joint that no
/// measurement reads is held rigid there), so the link's weight loads every measured joint
/// above it; those moving joints are returned second.
fn inertials(
    robot: &urdf::Robot,
    joints: &[JointSpec],
    path: &Path,
) -> Result<(Vec<LinkInertial>, Vec<String>), Error> {
    let mut out: Vec<LinkInertial> = Vec::new();
    let mut held: Vec<String> = Vec::new();
    for l in &robot.links {
        // Walk up from the link to the nearest measured moving joint, composing the origins
        // of the joints passed.
        let walk = urdf::walk_up(robot, &l.name, |joint| {
            joints.iter().any(|s| s.name == joint.name)
        });
        let Some(j) = (walk.stop).and_then(|stop| joints.iter().position(|s| s.name == stop.name))
        else {
            continue;
        };
        let frame = (walk.passed.iter()).fold(Isometry3::identity(), |frame, joint| {
            origin_of(joint) * frame
        });
        let passed: Vec<&str> = (walk.passed.iter())
            .filter(|joint| !matches!(joint.joint_type, urdf::JointType::Fixed))
            .map(|joint| joint.name.as_str())
            .collect();
        if l.inertial.mass.value > 0.0 {
            for name in passed {
                if !held.iter().any(|h| h == name) {
                    held.push(name.to_owned());
                }
            }
        }
        let (mass_kg, xyz) = urdf::inertial(l).map_err(|m| urdf_error(path, m))?;
        let name = &l.name;
        if mass_kg == 0.0 {
            continue;
        }
        let com = frame * Point3::from(xyz);
        out.push(LinkInertial {
            joint: j,
            link: name.clone(),
            mass_kg,
            com_m: [com.x, com.y, com.z],
        });
    }
    Ok((out, held))
}

/// Reads and parses a URDF, with XML errors located: [`read_urdf`].
fn read_robot(path: &Path) -> Result<Arc<urdf::Robot>, Error> {
    read_urdf(path)
}

/// URDF texts parsed last, with their descriptions, the latest last: a check or a calibration
/// reads one URDF many times (each set of tips, each hypothesis), and parsing the XML takes
/// milliseconds where reading the text takes microseconds.
static PARSED: Mutex<Vec<(String, Arc<urdf::Robot>)>> = Mutex::new(Vec::new());

/// URDF texts [`PARSED`] keeps.
const PARSED_KEPT: usize = 8;

/// A URDF's text; invalid UTF-8 is an [`Error::Xml`] at its line and column.
fn read_urdf_text(path: &Path) -> Result<String, Error> {
    Error::read_text(path, |line, column, message| Error::Xml {
        path: path.to_path_buf(),
        line,
        column,
        message,
    })
}

/// The description of the URDF at `path` as urdf-rs parses it, after the checks every import
/// makes (well-formed XML, one root, every joint's links defined, no loop). The file is read
/// each time; a text read before is not parsed again (the description is kept by its text, so
/// an edited file is parsed anew).
///
/// # Errors
///
/// [`Error::Io`] if the file cannot be read; [`Error::Xml`] (file:line:column) for malformed
/// XML; [`Error::UrdfStructure`] (file:line:column) for a joint naming an undefined link, a
/// link with two parent joints, several roots or a loop; [`Error::Urdf`] if urdf-rs cannot
/// parse it.
pub fn read_urdf(path: &Path) -> Result<Arc<urdf::Robot>, Error> {
    let text = read_urdf_text(path)?;
    let parsed = |cache: &mut Vec<(String, Arc<urdf::Robot>)>| {
        let at = cache.iter().position(|(t, _)| *t == text)?;
        let hit = cache.remove(at);
        let robot = Arc::clone(&hit.1);
        cache.push(hit);
        Some(robot)
    };
    if let Some(robot) = PARSED.lock().ok().as_deref_mut().and_then(parsed) {
        return Ok(robot);
    }
    check_xml(&text, path)?;
    let robot = urdf::parse(&text).map_err(|e| urdf_error(path, e.to_string()))?;
    check_tree(&robot, &text, path)?;
    let robot = Arc::new(robot);
    if let Ok(mut cache) = PARSED.lock() {
        if cache.len() >= PARSED_KEPT {
            cache.remove(0);
        }
        cache.push((text, Arc::clone(&robot)));
    }
    Ok(robot)
}

/// Longest chain, m (the sum of the `<origin xyz>` lengths from the root link to a tip), that
/// [`import_urdf`] accepts. The largest serial arms reach about 4 m and a mobile base adds a
/// few metres; a chain of 50 m or more is a URDF written in millimetres (URDF lengths are in
/// metres), whose calibration would fit millimetre-sized deviations to metre-sized links.
pub const MAX_CHAIN_LENGTH_M: f64 = 50.0;

/// `Ok` if the links and joints of `robot` form one tree: every joint's parent and child
/// link is defined, no link has two parent joints, and exactly one link has none (the root;
/// with none, the joints form a loop). Errors name the joint or link and its line in `text`.
fn check_tree(robot: &urdf::Robot, text: &str, path: &Path) -> Result<(), Error> {
    let at = |element: &str, name: &str, message: String| {
        let (line, column) = element_position(text, element, name);
        Error::UrdfStructure {
            path: path.to_path_buf(),
            line,
            column,
            message,
        }
    };
    // Names identify joints and links (parents, children, parameters): each must be unique.
    for (element, names) in [
        (
            "joint",
            robot
                .joints
                .iter()
                .map(|j| j.name.as_str())
                .collect::<Vec<_>>(),
        ),
        (
            "link",
            robot.links.iter().map(|l| l.name.as_str()).collect(),
        ),
    ] {
        for (i, name) in names.iter().enumerate() {
            if names.iter().take(i).any(|n| n == name) {
                let (line, column) = element_positions(text, element, name)
                    .get(1)
                    .copied()
                    .unwrap_or((0, 0));
                return Err(Error::UrdfStructure {
                    path: path.to_path_buf(),
                    line,
                    column,
                    message: format!(
                        "a second <{element}> named {name:?}: {element} names must be unique"
                    ),
                });
            }
        }
    }
    let links: std::collections::HashSet<&str> =
        robot.links.iter().map(|l| l.name.as_str()).collect();
    let mut parent_of: std::collections::HashMap<&str, &str> = std::collections::HashMap::new();
    for joint in &robot.joints {
        for (role, link) in [("parent", &joint.parent.link), ("child", &joint.child.link)] {
            if !links.contains(link.as_str()) {
                return Err(at(
                    "joint",
                    &joint.name,
                    format!(
                        "joint {:?}: {role} link {link:?} is not defined by any <link>",
                        joint.name
                    ),
                ));
            }
        }
        if let Some(first) = parent_of.insert(joint.child.link.as_str(), joint.name.as_str()) {
            return Err(at(
                "joint",
                &joint.name,
                format!(
                    "link {:?} has two parent joints, {first:?} and {:?}: a URDF is a tree",
                    joint.child.link, joint.name
                ),
            ));
        }
    }
    let roots: Vec<&str> = (robot.links.iter())
        .map(|l| l.name.as_str())
        .filter(|l| !parent_of.contains_key(l))
        .collect();
    match roots.as_slice() {
        [_] => Ok(()),
        [] => Err(at(
            "robot",
            &robot.name,
            "every link has a parent joint: the joints form a loop".to_owned(),
        )),
        [first, second, ..] => Err(at(
            "link",
            second,
            format!(
                "{} links have no parent joint ({}): a URDF is one tree with one root; link {second:?} is not connected to {first:?}",
                roots.len(),
                roots.join(", ")
            ),
        )),
    }
}

/// 1-based line and column of the `<{element} name="{name}"` tag in `text`, or (0, 0).
fn element_position(text: &str, element: &str, name: &str) -> (u64, u64) {
    element_positions(text, element, name)
        .first()
        .copied()
        .unwrap_or((0, 0))
}

/// 1-based line and column of every `<{element} name="{name}"` tag in `text`, in file order.
fn element_positions(text: &str, element: &str, name: &str) -> Vec<(u64, u64)> {
    let mut found_at = Vec::new();
    let open = format!("<{element}");
    let mut from = 0;
    while let Some(found) = text.get(from..).and_then(|t| t.find(&open)) {
        let start = from + found;
        let end = text
            .get(start..)
            .and_then(|t| t.find('>'))
            .map_or(text.len(), |e| start + e);
        let tag = text.get(start..end).unwrap_or("");
        let after = tag.get(open.len()..).unwrap_or("");
        if after.starts_with(char::is_whitespace)
            && (tag.contains(&format!("name=\"{name}\""))
                || tag.contains(&format!("name='{name}'")))
        {
            found_at.push(crate::line_column(text, start));
        }
        from = start + open.len();
    }
    found_at
}

/// `Err(`[`Error::UrdfStructure`]`)` if the `<origin xyz>` lengths of `chain` (root to tip)
/// add up to more than [`MAX_CHAIN_LENGTH_M`]: lengths in millimetres. The error points at the
/// longest origin's joint in the file at `text_path`.
fn check_chain_length(chain: &[&urdf::Joint], tip: &str, text_path: &Path) -> Result<(), Error> {
    let length = |j: &urdf::Joint| {
        let [x, y, z] = j.origin.xyz.0;
        (x * x + y * y + z * z).sqrt()
    };
    let total: f64 = chain.iter().map(|j| length(j)).sum();
    if total > MAX_CHAIN_LENGTH_M {
        let longest = chain.iter().max_by(|a, b| length(a).total_cmp(&length(b)));
        let text = std::fs::read_to_string(text_path).unwrap_or_default();
        let (name, (line, column), l) = longest.map_or((String::new(), (0, 0), 0.0), |j| {
            (
                j.name.clone(),
                element_position(&text, "joint", &j.name),
                length(j),
            )
        });
        return Err(Error::UrdfStructure {
            path: text_path.to_path_buf(),
            line,
            column,
            message: format!(
                "the chain to {tip:?} is {total:.1} m long (joint {name:?} alone {l:.1} m), more than {MAX_CHAIN_LENGTH_M} m: URDF lengths are in metres, these look like millimetres"
            ),
        });
    }
    Ok(())
}

fn urdf_error(path: &Path, message: String) -> Error {
    Error::Urdf {
        path: path.to_path_buf(),
        message,
    }
}

/// The joints from the root link down to `tip`, root first.
fn chain_to<'r>(
    robot: &'r urdf::Robot,
    tip: &str,
    path: &Path,
) -> Result<Vec<&'r urdf::Joint>, Error> {
    if !robot.links.iter().any(|l| l.name == tip) {
        return Err(Error::TipNotFound {
            path: path.to_path_buf(),
            tip: tip.to_owned(),
            available: robot.links.iter().map(|l| l.name.clone()).collect(),
        });
    }
    urdf::path_to(robot, tip).map_err(|e| urdf_error(path, e.to_string()))
}

/// How wide a continuous joint's limits are.
#[derive(Clone, Copy)]
enum Limits {
    /// [−π, π] (a device file's joint).
    Continuous1Turn,
    /// [−1000, 1000] rad (a tree's joint, read from a measurement file).
    Continuous1000,
}

/// The joint's origin as an isometry (m).
fn origin_of(joint: &urdf::Joint) -> Isometry3<f64> {
    let [x, y, z] = joint.origin.xyz.0;
    let [roll, pitch, yaw] = joint.origin.rpy.0;
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(roll, pitch, yaw),
    )
}

/// A URDF joint as a placement, with its joint entry if it moves.
fn placement_of(
    joint: &urdf::Joint,
    path: &Path,
    limits: Limits,
) -> Result<(Placement, Option<JointSpec>), Error> {
    let name = &joint.name;
    let (xyz, rpy) = urdf::origin(joint).map_err(|m| urdf_error(path, m))?;
    let prismatic = joint.joint_type == urdf::JointType::Prismatic;
    let axis = match joint.joint_type {
        urdf::JointType::Fixed => None,
        urdf::JointType::Revolute | urdf::JointType::Continuous | urdf::JointType::Prismatic => {
            Some(urdf::axis(joint).map_err(|m| urdf_error(path, m))?)
        }
        ref other => {
            return Err(Error::UnsupportedJoint {
                path: path.to_path_buf(),
                joint: name.clone(),
                kind: urdf::joint_type_name(other).to_owned(),
            });
        }
    };
    let spec = if axis.is_some() {
        let continuous = match limits {
            Limits::Continuous1Turn => (-std::f64::consts::PI, std::f64::consts::PI),
            Limits::Continuous1000 => (-1e3, 1e3),
        };
        let (lower, upper) = urdf::limits(joint, continuous).map_err(|m| urdf_error(path, m))?;
        Some(JointSpec {
            name: name.clone(),
            lower_rad: lower,
            upper_rad: upper,
            counts_per_rev: None,
        })
    } else {
        None
    };
    Ok((
        Placement {
            name: name.clone(),
            xyz_m: xyz,
            rpy_rad: rpy,
            axis,
            prismatic,
        },
        spec,
    ))
}

/// The text of `source_urdf` with the `<origin xyz rpy>` of each joint named in
/// `placements` set to the placement's `xyz_m` and `rpy_rad`.
///
/// Only those attribute values change (a `quat_xyzw` attribute is dropped, as it would
/// contradict `rpy`); comments, formatting and every other element stay byte for byte. A
/// joint without `<origin>` gets one as its first child. Numbers are written in Rust's
/// shortest form that parses back to the same `f64` (at most 17 significant digits).
/// Placement axes are not written (calibration moves origins, not axes). The result is
/// read back with urdf-rs and checked to hold exactly the new values.
///
/// # Errors
///
/// [`Error::Io`] if the file cannot be read; [`Error::Urdf`] if urdf-rs cannot parse it
/// or a named joint has no children; [`Error::Xml`] for malformed XML (file, line,
/// column); [`Error::UnknownJoint`] if a placement names no joint of the URDF;
/// [`Error::Parameter`] if a placement is given twice or holds a non-finite number.
pub fn write_calibrated_urdf(
    source_urdf: &Path,
    placements: &[Placement],
) -> Result<String, Error> {
    let path = source_urdf;
    let text = read_urdf_text(path)?;
    let urdf_err = |message: String| Error::Urdf {
        path: path.to_path_buf(),
        message,
    };

    let mut targets: HashMap<&str, &Placement> = HashMap::new();
    for p in placements {
        if p.xyz_m.iter().chain(&p.rpy_rad).any(|v| !v.is_finite()) {
            return Err(Error::Parameter {
                name: p.name.clone(),
                message: "placement xyz/rpy is not finite".into(),
            });
        }
        if targets.insert(&p.name, p).is_some() {
            return Err(Error::Parameter {
                name: p.name.clone(),
                message: "placement given twice".into(),
            });
        }
    }

    let edits = plan_edits(&text, path, &targets)?;
    urdf::parse(&text).map_err(|e| urdf_err(e.to_string()))?;
    if let Some(missing) = placements.iter().find(|p| !edits.joints.contains(&p.name)) {
        return Err(Error::UnknownJoint {
            path: path.to_path_buf(),
            joint: missing.name.clone(),
        });
    }
    let mut out = text.clone();
    let mut edits = edits.splices;
    edits.sort_by_key(|(range, _)| std::cmp::Reverse(range.start));
    for (range, replacement) in edits {
        if out.get(range.clone()).is_none() {
            return Err(urdf_err("internal error: edit outside the text".into()));
        }
        out.replace_range(range, &replacement);
    }

    let robot = urdf::parse(&out).map_err(|e| {
        urdf_err(format!(
            "internal error: the written URDF does not parse: {}",
            e.reason
        ))
    })?;
    for p in placements {
        let ok = (robot.joints.iter().filter(|j| j.name == p.name))
            .all(|j| j.origin.xyz.0 == p.xyz_m && j.origin.rpy.0 == p.rpy_rad);
        if !ok {
            return Err(urdf_err(format!(
                "internal error: joint {:?} does not read back with the new origin",
                p.name
            )));
        }
    }
    Ok(out)
}

/// Checks that `text` is well-formed XML, reporting the position of the first fault.
fn check_xml(text: &str, path: &Path) -> Result<(), Error> {
    plan_edits(text, path, &HashMap::new()).map(|_| ())
}

struct Edits {
    /// Byte range of the source → its replacement.
    splices: Vec<(Range<usize>, String)>,
    /// Names of the target joints found.
    joints: Vec<String>,
}

/// A target joint whose element is open.
struct OpenJoint<'p> {
    placement: &'p Placement,
    /// Byte offset just after `<joint …>`.
    start_tag_end: usize,
    /// Whitespace right after the start tag, reused to indent an inserted `<origin>`.
    indent: String,
    has_origin: bool,
}

fn plan_edits(
    text: &str,
    path: &Path,
    targets: &HashMap<&str, &Placement>,
) -> Result<Edits, Error> {
    let mut reader = Reader::from_str(text);
    let xml_err = |reader: &Reader<&[u8]>, message: String| {
        let (line, column) = line_column(text, reader.error_position() as usize);
        Error::Xml {
            path: path.to_path_buf(),
            line,
            column,
            message,
        }
    };
    let mut edits = Edits {
        splices: Vec::new(),
        joints: Vec::new(),
    };
    let mut depth = 0usize;
    let mut open: Option<OpenJoint<'_>> = None;
    // The top-level element being read (`joint "j2"`, `link "base"`), to name an origin.
    let mut parent = String::new();
    loop {
        let start = reader.buffer_position() as usize;
        let event = match reader.read_event() {
            Ok(event) => event,
            Err(e) => return Err(xml_err(&reader, e.to_string())),
        };
        let end = reader.buffer_position() as usize;
        match event {
            Event::Start(ref e) | Event::Empty(ref e) => {
                let is_empty = matches!(event, Event::Empty(_));
                let name = e.name();
                if depth == 1 {
                    let own = attribute(e, "name").ok().flatten().unwrap_or_default();
                    parent = format!("{} {own:?}", name.as_ref());
                }
                check_numbers(e, text, start, path, &parent)?;
                if name.as_ref() == "origin"
                    && let Ok(Some(xyz)) = attribute(e, "xyz")
                    && let Some(xyz) = parse_triple(&xyz)
                    // The position only for a value that fails: counting the lines up to
                    // every origin made reading a URDF quadratic in its length.
                    && xyz
                        .iter()
                        .any(|v| Error::check_length(path, 0, 0, "", *v).is_err())
                {
                    let (line, column) = line_column(text, start);
                    let what = format!("{parent} <origin xyz>");
                    for v in xyz {
                        Error::check_length(path, line, column, what.trim_start(), v)?;
                    }
                }
                if depth == 1 && name.as_ref() == "joint" {
                    let joint_name = attribute(e, "name")
                        .map_err(|m| xml_err(&reader, m))?
                        .unwrap_or_default();
                    if let Some(placement) = targets.get(joint_name.as_str()) {
                        if is_empty {
                            return Err(Error::Urdf {
                                path: path.to_path_buf(),
                                message: format!("joint {joint_name:?} has no children"),
                            });
                        }
                        edits.joints.push(joint_name);
                        open = Some(OpenJoint {
                            placement,
                            start_tag_end: end,
                            indent: String::new(),
                            has_origin: false,
                        });
                    }
                } else if let Some(joint) = open.as_mut().filter(|_| depth == 2)
                    && name.as_ref() == "origin"
                {
                    let tag = text.get(start..end).unwrap_or_default();
                    let new_tag = rewrite_origin_tag(tag, joint.placement)
                        .ok_or_else(|| xml_err(&reader, "malformed <origin> tag".into()))?;
                    edits.splices.push((start..end, new_tag));
                    joint.has_origin = true;
                }
                if !is_empty {
                    depth += 1;
                    if depth > MAX_XML_DEPTH {
                        let (line, column) = line_column(text, start);
                        return Err(Error::Xml {
                            path: path.to_path_buf(),
                            line,
                            column,
                            message: format!(
                                "elements nested more than {MAX_XML_DEPTH} deep (a URDF needs a handful)"
                            ),
                        });
                    }
                }
            }
            Event::End(_) => {
                depth = depth.saturating_sub(1);
                if depth == 1
                    && let Some(joint) = open.take()
                    && !joint.has_origin
                    && (joint.placement.xyz_m != [0.0; 3] || joint.placement.rpy_rad != [0.0; 3])
                {
                    let (xyz, rpy) = (joint.placement.xyz_m, joint.placement.rpy_rad);
                    let element = format!(
                        "{}<origin xyz=\"{}\" rpy=\"{}\"/>",
                        joint.indent,
                        triple(&xyz),
                        triple(&rpy)
                    );
                    let at = joint.start_tag_end;
                    edits.splices.push((at..at, element));
                }
            }
            Event::Text(_) => {
                if let Some(joint) = open.as_mut().filter(|j| j.start_tag_end == start) {
                    let raw = text.get(start..end).unwrap_or_default();
                    if raw.chars().all(char::is_whitespace) {
                        joint.indent = raw.to_owned();
                    }
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    Ok(edits)
}

/// `Err(`[`Error::UrdfStructure`]`)` at the tag if a numeric attribute of an `<origin>`
/// (`xyz`, `rpy`: three numbers), `<axis>` (`xyz`) or `<limit>` (`lower`, `upper`: one
/// number) is not written as plain numbers (`360mm`, `0,36`): URDF values carry no units
/// (lengths in m, angles in rad).
fn check_numbers(
    e: &BytesStart<'_>,
    text: &str,
    start: usize,
    path: &Path,
    parent: &str,
) -> Result<(), Error> {
    let tag = e.name();
    let attributes: &[(&str, usize)] = match tag.as_ref() {
        "origin" => &[("xyz", 3), ("rpy", 3)],
        "axis" => &[("xyz", 3)],
        "limit" => &[("lower", 1), ("upper", 1)],
        _ => return Ok(()),
    };
    let element = tag.as_ref().to_owned();
    for (attr, count) in attributes {
        let Ok(Some(value)) = attribute(e, attr) else {
            continue;
        };
        let cells: Vec<&str> = value.split_whitespace().collect();
        let bad = cells.iter().find(|c| c.parse::<f64>().is_err());
        if cells.len() == *count && bad.is_none() {
            continue;
        }
        let (line, column) = line_column(text, start);
        let what = if *count == 1 {
            "one number".to_owned()
        } else {
            format!("{count} numbers separated by spaces")
        };
        let unit = match (tag.as_ref(), *attr) {
            ("origin", "xyz") => " (m: URDF values carry no unit)",
            ("origin", "rpy") => " (rad: URDF values carry no unit)",
            ("limit", _) => " (rad, m for a prismatic joint: URDF values carry no unit)",
            _ => "",
        };
        let found = match bad {
            Some(cell) => format!("found {value:?} ({cell:?} is not a number)"),
            None => format!("found {value:?} ({} values)", cells.len()),
        };
        return Err(Error::UrdfStructure {
            path: path.to_path_buf(),
            line,
            column,
            message: format!(
                "{} <{element} {attr}>: expected {what}{unit}, {found}",
                parent.trim_start()
            ),
        });
    }
    Ok(())
}

/// The value of attribute `name` of `e`, if present.
fn attribute(e: &BytesStart<'_>, name: &str) -> Result<Option<String>, String> {
    let attr = e.try_get_attribute(name).map_err(|err| err.to_string())?;
    attr.map(|a| {
        a.normalized_value(XmlVersion::Implicit1_0)
            .map(|v| v.into_owned())
            .map_err(|err| err.to_string())
    })
    .transpose()
}

/// Three numbers separated by whitespace, as urdf-rs reads them.
fn parse_triple(text: &str) -> Option<[f64; 3]> {
    let values: Vec<f64> = text
        .split_whitespace()
        .map(str::parse)
        .collect::<Result<_, _>>()
        .ok()?;
    values.try_into().ok()
}

/// `x y z` with each number in shortest round-trip form.
fn triple(v: &[f64; 3]) -> String {
    format!("{:?} {:?} {:?}", v[0], v[1], v[2])
}

/// One attribute inside a start tag: its whole extent (with the whitespace before it) and
/// its value's extent, as byte ranges of the tag.
struct AttrSpan<'t> {
    name: &'t str,
    whole: Range<usize>,
    value: Range<usize>,
}

/// Scans the attributes of a start tag `<name a="…" b='…' …>` or `…/>`.
fn scan_attributes(tag: &str) -> Option<(Vec<AttrSpan<'_>>, usize)> {
    let bytes = tag.as_bytes();
    let mut i = 1 + bytes
        .get(1..)?
        .iter()
        .position(|b| b.is_ascii_whitespace() || *b == b'/' || *b == b'>')?;
    let mut name_end = i;
    let mut attrs = Vec::new();
    loop {
        let ws_start = i;
        while bytes.get(i).is_some_and(u8::is_ascii_whitespace) {
            i += 1;
        }
        match bytes.get(i)? {
            b'/' | b'>' => return Some((attrs, name_end)),
            _ => {}
        }
        let name_start = i;
        while bytes
            .get(i)
            .is_some_and(|b| !b.is_ascii_whitespace() && *b != b'=')
        {
            i += 1;
        }
        let name = tag.get(name_start..i)?;
        while bytes.get(i).is_some_and(u8::is_ascii_whitespace) {
            i += 1;
        }
        if *bytes.get(i)? != b'=' {
            return None;
        }
        i += 1;
        while bytes.get(i).is_some_and(u8::is_ascii_whitespace) {
            i += 1;
        }
        let quote = *bytes.get(i)?;
        if quote != b'"' && quote != b'\'' {
            return None;
        }
        let value_start = i + 1;
        let value_end = value_start + bytes.get(value_start..)?.iter().position(|b| *b == quote)?;
        i = value_end + 1;
        attrs.push(AttrSpan {
            name,
            whole: ws_start..i,
            value: value_start..value_end,
        });
        name_end = i;
    }
}

/// `tag` (`<origin …/>` or `<origin …>`) with `xyz` and `rpy` set to the placement's values
/// and `quat_xyzw` removed; `None` if the tag cannot be scanned.
fn rewrite_origin_tag(tag: &str, placement: &Placement) -> Option<String> {
    let (attrs, last_attr_end) = scan_attributes(tag)?;
    let targets = [("xyz", placement.xyz_m), ("rpy", placement.rpy_rad)];
    let mut splices: Vec<(Range<usize>, String)> = Vec::new();
    // Absent attributes are zero in URDF; only non-zero ones need inserting.
    let mut missing: Vec<(&str, [f64; 3])> = targets
        .into_iter()
        .filter(|(_, v)| *v != [0.0; 3])
        .collect();
    for attr in &attrs {
        if let Some((_, new)) = targets.iter().find(|(name, _)| *name == attr.name) {
            // A value that already reads as the new one keeps its spelling.
            if parse_triple(tag.get(attr.value.clone())?) != Some(*new) {
                splices.push((attr.value.clone(), triple(new)));
            }
        } else if attr.name == "quat_xyzw" {
            splices.push((attr.whole.clone(), String::new()));
            // Without the quaternion, a missing rpy means zero: it must be written.
            if let Some((_, rpy)) = targets.get(1) {
                missing.push(("rpy", *rpy));
            }
        }
    }
    missing.retain(|(name, _)| !attrs.iter().any(|a| a.name == *name));
    missing.dedup_by_key(|(name, _)| *name);
    let missing: Vec<(&str, String)> = missing.iter().map(|(n, v)| (*n, triple(v))).collect();
    let inserted: String = missing
        .iter()
        .map(|(name, value)| format!(" {name}=\"{value}\""))
        .collect();
    if !inserted.is_empty() {
        splices.push((last_attr_end..last_attr_end, inserted));
    }
    splices.sort_by_key(|(range, _)| std::cmp::Reverse(range.start));
    let mut out = tag.to_owned();
    for (range, replacement) in splices {
        out.get(range.clone())?;
        out.replace_range(range, &replacement);
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn placement(xyz: [f64; 3], rpy: [f64; 3]) -> Placement {
        Placement {
            name: "j".into(),
            xyz_m: xyz,
            rpy_rad: rpy,
            axis: None,
            prismatic: false,
        }
    }

    #[test]
    fn origin_tag_keeps_order_quotes_and_other_attributes() {
        let p = placement([0.5, -1e-7, 0.0], [0.1, 0.2, 0.3]);
        let tag = "<origin rpy='0 0 0'  foo=\"a>b\" xyz=\"0 0 0.36\"/>";
        assert_eq!(
            rewrite_origin_tag(tag, &p).as_deref(),
            Some("<origin rpy='0.1 0.2 0.3'  foo=\"a>b\" xyz=\"0.5 -1e-7 0.0\"/>")
        );
    }

    #[test]
    fn origin_tag_gets_missing_attributes_and_loses_quaternion() {
        let p = placement([1.0, 2.0, 3.0], [0.0, 0.0, 0.5]);
        assert_eq!(
            rewrite_origin_tag("<origin xyz=\"0 0 0\" quat_xyzw=\"0 0 0 1\" />", &p).as_deref(),
            Some("<origin xyz=\"1.0 2.0 3.0\" rpy=\"0.0 0.0 0.5\" />")
        );
        assert_eq!(
            rewrite_origin_tag("<origin/>", &p).as_deref(),
            Some("<origin xyz=\"1.0 2.0 3.0\" rpy=\"0.0 0.0 0.5\"/>")
        );
        assert_eq!(
            rewrite_origin_tag("<origin>", &p).as_deref(),
            Some("<origin xyz=\"1.0 2.0 3.0\" rpy=\"0.0 0.0 0.5\">")
        );
    }

    #[test]
    fn unchanged_values_keep_their_spelling() {
        let p = placement([0.0, 0.0, 0.36], [0.0; 3]);
        let tag = "<origin xyz=\"0 0 3.6e-1\" rpy=\"0 0 0\"/>";
        assert_eq!(rewrite_origin_tag(tag, &p).as_deref(), Some(tag));
        assert_eq!(
            rewrite_origin_tag("<origin xyz=\"0 0 .36\"/>", &p).as_deref(),
            Some("<origin xyz=\"0 0 .36\"/>")
        );
    }

    #[test]
    fn malformed_tag_is_none() {
        let p = placement([0.0; 3], [0.0; 3]);
        assert!(rewrite_origin_tag("<origin xyz=\"0 0 0/>", &p).is_none());
        assert!(rewrite_origin_tag("<origin xyz/>", &p).is_none());
    }
}
