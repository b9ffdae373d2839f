//! The URDF reader every crate shares: a URDF's text parsed into its description (links with
//! their `<inertial>` masses, joints with their type, `<origin>`, `<axis>`, `<limit>`, parent
//! and child link) and the walks over its tree that every reader makes (root to a tip, a link
//! up to the nearest joint of a set).
//!
//! `hapcal-io` adds its checks (well-formed XML, one tree, file positions) and converts the
//! description into kinematics types; the runtime converts it into its fixed-size model.
//! Neither parses URDF text itself.

/// The parsed description: [`Robot`] (links and joints), as urdf-rs reads it.
pub use urdf_rs::{Joint, JointType, Link, Robot};

/// A joint type as a URDF file spells it in `<joint type="…">` (URDF specification, `joint`
/// element): what a message names an unsupported joint by.
pub fn joint_type_name(kind: &JointType) -> &'static str {
    match kind {
        JointType::Revolute => "revolute",
        JointType::Continuous => "continuous",
        JointType::Prismatic => "prismatic",
        JointType::Fixed => "fixed",
        JointType::Floating => "floating",
        JointType::Planar => "planar",
        JointType::Spherical => "spherical",
    }
}

/// Text that is not a URDF ([`parse`]); displayed as `not a valid URDF: ` and the reason.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NotUrdf {
    /// urdf-rs's reason.
    pub reason: String,
}

impl std::fmt::Display for NotUrdf {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "not a valid URDF: {}", self.reason)
    }
}

impl std::error::Error for NotUrdf {}

/// How deep a URDF's elements may nest: a URDF needs 5 or 6 levels (robot, link, visual,
/// geometry, mesh), vendor extensions a few more. Deeper nesting is refused before urdf-rs,
/// whose recursive descent overflows the stack on some 10⁴ levels.
pub const MAX_XML_DEPTH: usize = 64;

/// Parses a URDF's text into its description.
///
/// # Errors
/// [`NotUrdf`]: elements nested deeper than [`MAX_XML_DEPTH`] (with the line and column of
/// the first element past it), or text that urdf-rs cannot read as a URDF.
pub fn parse(text: &str) -> Result<Robot, NotUrdf> {
    check_depth(text)?;
    urdf_rs::read_from_string(text).map_err(|e| NotUrdf {
        reason: e.to_string(),
    })
}

/// Refuses elements nested deeper than [`MAX_XML_DEPTH`], scanning the text's start and end
/// tags without recursion. Text that is not well-formed XML is left to urdf-rs, which says
/// why (the scan stops there, so nothing past it reaches urdf-rs any deeper than the scan
/// allowed before it: urdf-rs stops at the same fault).
fn check_depth(text: &str) -> Result<(), NotUrdf> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::Reader::from_str(text);
    let mut depth = 0usize;
    loop {
        let start = usize::try_from(reader.buffer_position()).unwrap_or(usize::MAX);
        match reader.read_event() {
            Ok(Event::Start(_)) => {
                depth += 1;
                if depth > MAX_XML_DEPTH {
                    let (line, column) = crate::locate::line_column(text, start);
                    return Err(NotUrdf {
                        reason: format!(
                            "line {line}, column {column}: elements nested more than \
                             {MAX_XML_DEPTH} deep (a URDF needs a handful)"
                        ),
                    });
                }
            }
            Ok(Event::End(_)) => depth = depth.saturating_sub(1),
            Ok(Event::Eof) | Err(_) => return Ok(()),
            Ok(_) => {}
        }
    }
}

/// The joint whose child is `link` (the first in file order, should a malformed file give
/// the link two); `None` for the root link or a link no joint names.
pub fn parent_joint<'r>(robot: &'r Robot, link: &str) -> Option<&'r Joint> {
    robot.joints.iter().find(|j| j.child.link == link)
}

/// A joint's `<origin>`: `xyz` (m) and `rpy` (rad, roll-pitch-yaw about fixed x, y, z), the
/// one check of it every reader makes.
///
/// # Errors
/// A number that is not finite: `joint "j": origin xyz … rpy … is not finite`.
pub fn origin(joint: &Joint) -> Result<([f64; 3], [f64; 3]), String> {
    let (xyz, rpy) = (joint.origin.xyz.0, joint.origin.rpy.0);
    if xyz.iter().chain(&rpy).any(|v| !v.is_finite()) {
        return Err(format!(
            "joint {:?}: origin xyz {xyz:?} rpy {rpy:?} is not finite",
            joint.name
        ));
    }
    Ok((xyz, rpy))
}

/// Shortest `<axis xyz>` (its Euclidean norm, in the joint's frame) that has a direction.
pub const MIN_AXIS_NORM: f64 = 1e-12;

/// A moving joint's `<axis xyz>` as written (not normalised), in the joint's frame.
///
/// # Errors
/// An axis that is not finite or shorter than [`MIN_AXIS_NORM`]: `joint "j": axis … has no
/// direction`.
pub fn axis(joint: &Joint) -> Result<[f64; 3], String> {
    let axis = joint.axis.xyz.0;
    let norm = axis.iter().map(|a| a * a).sum::<f64>().sqrt();
    if !norm.is_finite() || norm < MIN_AXIS_NORM {
        return Err(format!(
            "joint {:?}: axis {axis:?} has no direction",
            joint.name
        ));
    }
    Ok(axis)
}

/// A moving joint's limits `(lower, upper)`: its `<limit>` (rad; m for a prismatic joint), or
/// `continuous` for a continuous joint (whose `<limit>` holds none), which is not checked.
///
/// # Errors
/// `<limit>` bounds that are not finite with lower < upper, naming the joint, the bounds and
/// their unit.
pub fn limits(joint: &Joint, continuous: (f64, f64)) -> Result<(f64, f64), String> {
    if joint.joint_type == JointType::Continuous {
        return Ok(continuous);
    }
    let (lower, upper) = (joint.limit.lower, joint.limit.upper);
    if !(lower.is_finite() && upper.is_finite() && lower < upper) {
        let unit = if joint.joint_type == JointType::Prismatic {
            "m"
        } else {
            "rad"
        };
        return Err(format!(
            "joint {:?}: limits [{lower}, {upper}] {unit} are not finite with lower < upper",
            joint.name
        ));
    }
    Ok((lower, upper))
}

/// A link's `<inertial>`: its mass (kg) and centre of mass (m, in the link's frame).
///
/// # Errors
/// A mass that is not finite and non-negative, or a centre of mass that is not finite:
/// `link "l": inertial mass … kg at … m is not a finite, non-negative mass at a finite point`.
pub fn inertial(link: &Link) -> Result<(f64, [f64; 3]), String> {
    let mass_kg = link.inertial.mass.value;
    let xyz = link.inertial.origin.xyz.0;
    if !(mass_kg.is_finite() && mass_kg >= 0.0) || xyz.iter().any(|v| !v.is_finite()) {
        return Err(format!(
            "link {:?}: inertial mass {mass_kg} kg at {xyz:?} m is not a finite, non-negative \
             mass at a finite point",
            link.name
        ));
    }
    Ok((mass_kg, xyz))
}

/// Why [`path_to`] found no path.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PathError {
    /// Link `link` is the child of two joints, `first` and `second` (file order).
    TwoParents {
        /// The link.
        link: String,
        /// Its first parent joint.
        first: String,
        /// Its second parent joint.
        second: String,
    },
    /// The joints above `tip` form a loop.
    Loop {
        /// The link the walk started from.
        tip: String,
    },
}

impl std::fmt::Display for PathError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PathError::TwoParents {
                link,
                first,
                second,
            } => write!(
                f,
                "link {link:?} has two parent joints, {first:?} and {second:?}"
            ),
            PathError::Loop { tip } => write!(f, "the joints above link {tip:?} form a loop"),
        }
    }
}

impl std::error::Error for PathError {}

/// The joints from the root link down to the link `tip`, root first: from `tip`, each link's
/// parent joint up to a link without one. Empty for the root link (or a link no joint names:
/// whether `tip` is a link at all is the caller's check).
///
/// # Errors
/// [`PathError::TwoParents`] for a link on the way that is the child of two joints;
/// [`PathError::Loop`] when the walk passes more joints than the robot has.
pub fn path_to<'r>(robot: &'r Robot, tip: &str) -> Result<Vec<&'r Joint>, PathError> {
    let mut path = Vec::new();
    let mut link = tip;
    loop {
        let mut parents = robot.joints.iter().filter(|j| j.child.link == link);
        let Some(joint) = parents.next() else { break };
        if let Some(other) = parents.next() {
            return Err(PathError::TwoParents {
                link: link.to_owned(),
                first: joint.name.clone(),
                second: other.name.clone(),
            });
        }
        if path.len() >= robot.joints.len() {
            return Err(PathError::Loop {
                tip: tip.to_owned(),
            });
        }
        path.push(joint);
        link = &joint.parent.link;
    }
    path.reverse();
    Ok(path)
}

/// The walk from a link up to the nearest joint above it that `stop` accepts
/// ([`walk_up`]).
#[derive(Clone, Debug)]
pub struct WalkUp<'r> {
    /// The joints passed on the way, nearest the link first (`stop` refused each).
    pub passed: Vec<&'r Joint>,
    /// The joint `stop` accepted; `None` when the walk reached the root link (or passed as
    /// many joints as the robot has) first.
    pub stop: Option<&'r Joint>,
}

/// Walks from `link` up its parent joints ([`parent_joint`]) to the nearest joint that `stop`
/// accepts: the moving joint whose frame carries a link's mass, the path a link hangs from.
/// Bounded by the robot's joint count (a loop ends the walk without a stop).
pub fn walk_up<'r>(robot: &'r Robot, link: &str, stop: impl Fn(&Joint) -> bool) -> WalkUp<'r> {
    let mut passed = Vec::new();
    let mut at = link;
    for _ in 0..=robot.joints.len() {
        let Some(joint) = parent_joint(robot, at) else {
            break;
        };
        if stop(joint) {
            return WalkUp {
                passed,
                stop: Some(joint),
            };
        }
        passed.push(joint);
        at = &joint.parent.link;
    }
    WalkUp { passed, stop: None }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nesting_past_the_limit_is_refused_at_its_line_without_overflowing_the_stack() {
        // 200,000 levels overflowed the main thread's stack in urdf-rs before the check.
        let n = 200_000;
        let text = format!(
            "<robot name=\"r\">\n<link name=\"a\"/>\n{}{}</robot>",
            "<x>".repeat(n),
            "</x>".repeat(n)
        );
        let e = parse(&text).unwrap_err();
        // The robot is level 1, so the 64th <x> is the first element past the limit: line 3,
        // column 1 + 63·3.
        assert_eq!(
            e.reason,
            format!(
                "line 3, column {}: elements nested more than {MAX_XML_DEPTH} deep (a URDF needs a handful)",
                1 + 63 * 3
            )
        );
        // At the limit the scan passes it on to urdf-rs.
        let at_limit = format!(
            "<robot name=\"r\"><link name=\"a\"/>{}{}</robot>",
            "<x>".repeat(MAX_XML_DEPTH - 1),
            "</x>".repeat(MAX_XML_DEPTH - 1)
        );
        assert!(check_depth(&at_limit).is_ok());
    }

    const ARM: &str = r#"<robot name="arm">
        <link name="base"/>
        <link name="upper"><inertial><mass value="2.0"/><origin xyz="0 0 0.1"/>
            <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
        <link name="hand"/>
        <link name="tool"/>
        <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
            <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
            <limit lower="-1" upper="1" effort="0" velocity="0"/></joint>
        <joint name="elbow" type="revolute"><parent link="upper"/><child link="hand"/>
            <origin xyz="0 0 0.4"/><axis xyz="0 1 0"/>
            <limit lower="-2" upper="2" effort="0" velocity="0"/></joint>
        <joint name="flange" type="fixed"><parent link="hand"/><child link="tool"/>
            <origin xyz="0 0 0.05"/></joint>
    </robot>"#;

    #[test]
    fn joints_and_links_are_checked_once() -> Result<(), Box<dyn std::error::Error>> {
        let robot = parse(ARM)?;
        let shoulder = &robot.joints[0];
        assert_eq!(super::origin(shoulder)?, ([0.0, 0.0, 0.3], [0.0; 3]));
        assert_eq!(super::axis(shoulder)?, [0.0, 0.0, 1.0]);
        assert_eq!(super::limits(shoulder, (-9.0, 9.0))?, (-1.0, 1.0));
        assert_eq!(super::inertial(&robot.links[1])?, (2.0, [0.0, 0.0, 0.1]));
        let bad = ARM
            .replace(
                r#"<origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>"#,
                r#"<origin xyz="0 0 inf"/><axis xyz="0 0 0"/>"#,
            )
            .replace(r#"lower="-2" upper="2""#, r#"lower="2" upper="-2""#)
            .replace(r#"<mass value="2.0"/>"#, r#"<mass value="-1"/>"#)
            .replace(
                r#"type="revolute"><parent link="base"/>"#,
                r#"type="continuous"><parent link="base"/>"#,
            );
        let robot = parse(&bad)?;
        let (shoulder, elbow) = (&robot.joints[0], &robot.joints[1]);
        assert!(super::origin(shoulder).is_err_and(|m| m.contains("is not finite")));
        assert!(
            super::axis(shoulder).is_err_and(|m| m.contains("[0.0, 0.0, 0.0] has no direction"))
        );
        // A continuous joint's range is the caller's.
        assert_eq!(super::limits(shoulder, (-9.0, 9.0))?, (-9.0, 9.0));
        assert!(super::limits(elbow, (-9.0, 9.0)).is_err_and(|m| m.contains("[2, -2] rad")));
        assert!(super::inertial(&robot.links[1]).is_err_and(|m| m.contains("mass -1 kg")));
        Ok(())
    }

    fn names(joints: &[&Joint]) -> Vec<String> {
        joints.iter().map(|j| j.name.clone()).collect()
    }

    #[test]
    fn path_runs_from_the_root_to_the_tip() -> Result<(), Box<dyn std::error::Error>> {
        let robot = parse(ARM)?;
        assert_eq!(
            names(&path_to(&robot, "tool")?),
            ["shoulder", "elbow", "flange"]
        );
        assert!(path_to(&robot, "base")?.is_empty());
        assert_eq!(robot.links[1].inertial.mass.value, 2.0);
        Ok(())
    }

    #[test]
    fn walk_up_stops_at_the_first_accepted_joint() -> Result<(), Box<dyn std::error::Error>> {
        let robot = parse(ARM)?;
        let walk = walk_up(&robot, "tool", |j| j.name == "shoulder");
        assert_eq!(names(&walk.passed), ["flange", "elbow"]);
        assert_eq!(walk.stop.map(|j| j.name.as_str()), Some("shoulder"));
        let none = walk_up(&robot, "tool", |_| false);
        assert_eq!(none.passed.len(), 3);
        assert!(none.stop.is_none());
        Ok(())
    }

    #[test]
    fn a_link_with_two_parents_and_a_loop_are_refused() -> Result<(), Box<dyn std::error::Error>> {
        for (extra_joint, refusal) in [
            (
                r#"<joint name="extra" type="fixed"><parent link="base"/><child link="hand"/></joint>"#,
                "link \"hand\" has two parent joints, \"elbow\" and \"extra\"",
            ),
            (
                r#"<joint name="back" type="fixed"><parent link="hand"/><child link="base"/></joint>"#,
                "the joints above link \"tool\" form a loop",
            ),
        ] {
            let robot = parse(&ARM.replace("</robot>", &format!("{extra_joint}</robot>")))?;
            assert_eq!(
                path_to(&robot, "tool").err().map(|e| e.to_string()),
                Some(refusal.to_owned())
            );
        }
        assert!(parse("<robot").is_err_and(|e| e.to_string().starts_with("not a valid URDF: ")));
        Ok(())
    }
}
