//! Kinematic trees: several tips (several markers on one hand, two arms on one torso) that
//! share one parameter vector and one joint vector, and the unknown frames of a measuring
//! instrument and of the markers it sees.

use std::collections::HashMap;

use hapcal_contract::{ElementField, ValueName};
use nalgebra::Isometry3;

use crate::placement::push_deviation;
use crate::{Chain, Error, Factor, Motion, ParamInfo, ParamUnit, Placement};

/// A nominal frame whose six deviations `Tx·Ty·Tz·Rx·Ry·Rz` are identified: the instrument's
/// frame relative to the robot base, or a marker's frame on its link.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameSpec {
    /// Frame name; becomes the element name and the parameter prefix (`instrument.x`, …).
    pub name: String,
    /// Nominal transform (m): the base frame in the instrument frame, or the marker frame in
    /// its tip frame.
    pub nominal: Isometry3<f64>,
}

/// A kinematic tree: one [`Chain`] per tip, all sharing one parameter vector `x` and one
/// joint vector `q` (the same [`Chain::params`] and [`Chain::joint_names`] on every tip, each
/// tip's factors using the entries on its path; a parameter off a tip's path has a zero
/// Jacobian column on that tip).
///
/// Valid by construction: built by [`Tree::single`], [`Tree::from_placement_paths`] or
/// derived by [`Tree::with_joint_offsets`] and [`Tree::with_frames`].
#[derive(Clone, Debug, PartialEq)]
pub struct Tree {
    tips: Vec<Chain>,
    /// Indices of the instrument and marker frame parameters ([`Tree::with_frames`]).
    frames: Vec<usize>,
}

impl Tree {
    /// The tree of one chain (one tip).
    pub fn single(chain: Chain) -> Tree {
        Tree {
            tips: vec![chain],
            frames: Vec::new(),
        }
    }

    /// A tree from root-to-tip URDF placement paths, one per tip ([`Chain::from_placements`]
    /// for each). Joints, elements and parameters with the same name on several paths (the
    /// shared links, e.g. a torso under two arms) are one entry; joints are numbered in order
    /// of first appearance, path by path.
    ///
    /// # Errors
    /// [`Error::EmptyChain`] without a path; whatever [`Chain::from_placements`] reports for
    /// a path; [`Error::DuplicateName`] if a shared name means two different things (a joint
    /// on one path, a parameter's unit on another).
    pub fn from_placement_paths(paths: &[Vec<Placement>]) -> Result<Tree, Error> {
        if paths.is_empty() {
            return Err(Error::EmptyChain);
        }
        let chains = paths
            .iter()
            .map(|p| Chain::from_placements(p))
            .collect::<Result<Vec<_>, _>>()?;
        Tree::merge(&chains)
    }

    /// Merges chains whose joints, elements and parameters are identified by name.
    fn merge(chains: &[Chain]) -> Result<Tree, Error> {
        let mut joints: Vec<String> = Vec::new();
        let mut elements: Vec<String> = Vec::new();
        let mut params: Vec<ParamInfo> = Vec::new();
        let mut joint_of: HashMap<String, usize> = HashMap::new();
        let mut element_of: HashMap<String, usize> = HashMap::new();
        let mut param_of: HashMap<String, usize> = HashMap::new();
        let mut maps = Vec::with_capacity(chains.len());
        for chain in chains {
            let jmap: Vec<usize> = (chain.joint_names().iter())
                .map(|n| {
                    *joint_of.entry(n.clone()).or_insert_with(|| {
                        joints.push(n.clone());
                        joints.len() - 1
                    })
                })
                .collect();
            let emap: Vec<usize> = (chain.element_names().iter())
                .map(|n| {
                    *element_of.entry(n.clone()).or_insert_with(|| {
                        elements.push(n.clone());
                        elements.len() - 1
                    })
                })
                .collect();
            let mut pmap = Vec::with_capacity(chain.n_params());
            for p in chain.params() {
                let index = match param_of.get(&p.name) {
                    Some(&i) => {
                        if params[i].unit != p.unit || params[i].element != emap[p.element] {
                            return Err(Error::DuplicateName {
                                kind: "parameter",
                                name: p.name.clone(),
                            });
                        }
                        i
                    }
                    None => {
                        params.push(ParamInfo {
                            name: p.name.clone(),
                            unit: p.unit,
                            element: emap[p.element],
                        });
                        param_of.insert(p.name.clone(), params.len() - 1);
                        params.len() - 1
                    }
                };
                pmap.push(index);
            }
            maps.push((jmap, pmap));
        }
        let tips = chains
            .iter()
            .zip(&maps)
            .map(|(chain, (jmap, pmap))| {
                let factors = chain
                    .factors()
                    .iter()
                    .map(|f| remap(f, |p| pmap[p], |j| jmap[j]))
                    .collect();
                Chain::from_factors(factors, params.clone(), joints.clone(), elements.clone())
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Tree {
            tips,
            frames: Vec::new(),
        })
    }

    /// Indices (into [`Tree::params`]) of the instrument and marker frame parameters, the
    /// nuisance parameters of a tree built by [`Tree::with_frames`]; empty otherwise.
    pub fn frame_params(&self) -> &[usize] {
        &self.frames
    }

    /// The chain of each tip, in the order given; every one has [`Tree::n_params`]
    /// parameters and [`Tree::joint_names`] joints.
    pub fn tips(&self) -> &[Chain] {
        &self.tips
    }

    /// Number of parameter deviations, the length of `x`.
    pub fn n_params(&self) -> usize {
        self.tips[0].n_params()
    }

    /// Names, units and owners of the entries of `x`.
    pub fn params(&self) -> &[ParamInfo] {
        self.tips[0].params()
    }

    /// Joint names, the order of `q`.
    pub fn joint_names(&self) -> &[String] {
        self.tips[0].joint_names()
    }

    /// Number of joints, the length of `q`.
    pub fn n_joints(&self) -> usize {
        self.tips[0].n_joints()
    }

    /// Per joint, the index in `x` of its offset: the deviation added to the joint value in
    /// the joint's own screw (`dtheta` of a revolute D-H row, `{joint}.offset` after
    /// [`Tree::with_joint_offsets`]); `None` for a joint whose screw carries no parameter.
    pub fn joint_offset_params(&self) -> Vec<Option<usize>> {
        let mut out = vec![None; self.n_joints()];
        for chain in &self.tips {
            for f in chain.factors() {
                if let Factor::Screw {
                    param: Some(p),
                    joint: Some(j),
                    ..
                } = f
                {
                    out[*j] = Some(*p);
                }
            }
        }
        out
    }

    /// The same tree with an offset parameter `{joint}.offset` (rad for a revolute joint, m
    /// for a prismatic one) on every joint whose screw has none, appended after the existing
    /// parameters; joints that already have one (D-H `dtheta`) are unchanged. The offset is
    /// added to the joint value (`q + offset`), the encoder zero of a revolute joint.
    pub fn with_joint_offsets(&self) -> Tree {
        let mut params = self.params().to_vec();
        let mut new_param: HashMap<usize, usize> = HashMap::new();
        let existing = self.joint_offset_params();
        for chain in &self.tips {
            for f in chain.factors() {
                if let Factor::Screw {
                    motion,
                    param: None,
                    joint: Some(j),
                    ..
                } = f
                    && existing[*j].is_none()
                    && !new_param.contains_key(j)
                {
                    let name = &self.joint_names()[*j];
                    let element = (chain.element_names().iter())
                        .position(|e| e == name)
                        .unwrap_or(0);
                    params.push(ParamInfo {
                        name: ValueName::Element {
                            element: name.clone(),
                            field: ElementField::Offset,
                        }
                        .to_string(),
                        unit: match motion {
                            Motion::Rotation => ParamUnit::Radian,
                            Motion::Translation => ParamUnit::Meter,
                        },
                        element,
                    });
                    new_param.insert(*j, params.len() - 1);
                }
            }
        }
        let tips = self
            .tips
            .iter()
            .map(|chain| {
                let factors = chain
                    .factors()
                    .iter()
                    .map(|f| match f {
                        Factor::Screw {
                            motion,
                            axis,
                            nominal,
                            param: None,
                            joint: Some(j),
                        } => Factor::Screw {
                            motion: *motion,
                            axis: *axis,
                            nominal: *nominal,
                            param: new_param.get(j).copied(),
                            joint: Some(*j),
                        },
                        other => other.clone(),
                    })
                    .collect();
                Chain {
                    factors,
                    params: params.clone(),
                    joint_names: chain.joint_names().to_vec(),
                    element_names: chain.element_names().to_vec(),
                }
            })
            .collect();
        // Appended offsets leave the indices of existing parameters unchanged.
        Tree {
            tips,
            frames: self.frames.clone(),
        }
    }

    /// The tree seen by an instrument: `x = [instrument (6) | this tree's parameters |
    /// 6 per marker]`, and one tip per marker `k`, `markers[k] = (tip, frame)`:
    ///
    /// `instrument_T_marker(x, q) = base.nominal · Δ_instrument · tip_chain(x, q) ·
    /// frame.nominal · Δ_k`,   `Δ = Tx·Ty·Tz·Rx·Ry·Rz`
    ///
    /// with parameters `{name}.x`, `.y`, `.z` (m), `.rx`, `.ry`, `.rz` (rad) of `base` and of
    /// each marker frame (hand-eye / robot-world calibration, Zhuang, Roth & Sudhakar 1994).
    /// Without markers, the tips are this tree's tips behind the instrument frame.
    ///
    /// # Errors
    /// [`Error::JointOutOfRange`] (as a factor index of `usize::MAX`) for a marker on a tip
    /// the tree does not have; [`Error::NotFinite`] for a non-finite nominal frame;
    /// [`Error::DuplicateName`] if a frame's name is an element name already.
    pub fn with_frames(
        &self,
        base: &FrameSpec,
        markers: &[(usize, FrameSpec)],
    ) -> Result<Tree, Error> {
        let mut params = Vec::with_capacity(self.n_params() + 6 + 6 * markers.len());
        let mut factors_base = vec![Factor::Fixed(base.nominal)];
        let mut elements = vec![base.name.clone()];
        push_deviation(&mut factors_base, &mut params, &base.name, 0);
        let mut frames: Vec<usize> = (0..params.len()).collect();
        let shift = params.len();
        elements.extend(self.tips[0].element_names().iter().cloned());
        params.extend(self.params().iter().map(|p| ParamInfo {
            name: p.name.clone(),
            unit: p.unit,
            element: p.element + 1,
        }));
        let mut ends = Vec::new();
        for (tip, frame) in markers {
            if *tip >= self.tips.len() {
                return Err(Error::JointOutOfRange {
                    factor: usize::MAX,
                    index: *tip,
                    n_joints: self.tips.len(),
                });
            }
            let mut f = vec![Factor::Fixed(frame.nominal)];
            let element = elements.len();
            elements.push(frame.name.clone());
            let first = params.len();
            push_deviation(&mut f, &mut params, &frame.name, element);
            frames.extend(first..params.len());
            ends.push((*tip, f));
        }
        if ends.is_empty() {
            ends = (0..self.tips.len()).map(|t| (t, Vec::new())).collect();
        }
        let tips = ends
            .into_iter()
            .map(|(tip, end)| {
                let mut factors = factors_base.clone();
                factors.extend(
                    self.tips[tip]
                        .factors()
                        .iter()
                        .map(|f| remap(f, |p| p + shift, |j| j)),
                );
                factors.extend(end);
                Chain::from_factors(
                    factors,
                    params.clone(),
                    self.joint_names().to_vec(),
                    elements.clone(),
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Tree { tips, frames })
    }
}

/// `factor` with its parameter and joint indices mapped.
fn remap(
    factor: &Factor,
    param: impl Fn(usize) -> usize,
    joint: impl Fn(usize) -> usize,
) -> Factor {
    match factor {
        Factor::Fixed(t) => Factor::Fixed(*t),
        Factor::Screw {
            motion,
            axis,
            nominal,
            param: p,
            joint: j,
        } => Factor::Screw {
            motion: *motion,
            axis: *axis,
            nominal: *nominal,
            param: p.map(&param),
            joint: j.map(&joint),
        },
    }
}
