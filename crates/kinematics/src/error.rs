//! The crate's error type.

/// Why a chain description was rejected by [`Chain::from_dh`](crate::Chain::from_dh),
/// [`Chain::from_placements`](crate::Chain::from_placements) or
/// [`Chain::from_factors`](crate::Chain::from_factors).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The description has no rows, placements or factors.
    #[error("empty chain: no rows, placements or factors")]
    EmptyChain,
    /// A number in the description is NaN or infinite.
    #[error("{element}: {field} is not finite ({value})")]
    NotFinite {
        /// Element (D-H row `row{i}`, placement name or `factor{k}`) holding the value.
        element: String,
        /// Field name, e.g. `a_m` or `xyz_m[1]`.
        field: String,
        /// The offending value.
        value: f64,
    },
    /// A placement's joint axis has (near) zero length, so it has no direction.
    #[error("{element}: joint axis {axis:?} has zero length")]
    ZeroAxis {
        /// Placement name.
        element: String,
        /// The axis as given.
        axis: [f64; 3],
    },
    /// A factor's screw axis is not a unit vector (`|norm − 1| > 1e-9`).
    #[error("factor {factor}: screw axis has norm {norm}, expected 1")]
    AxisNotUnit {
        /// Index of the factor.
        factor: usize,
        /// Norm of its axis.
        norm: f64,
    },
    /// The D-H rows' joint indices are not exactly `0..n_joints`, each used once.
    #[error("joint indices must be 0..n, each used once; found {found:?}")]
    JointIndices {
        /// The joint indices of the rows, in row order.
        found: Vec<usize>,
    },
    /// A factor refers to a parameter that does not exist.
    #[error("factor {factor}: parameter index {index} is out of range ({n_params} parameters)")]
    ParamOutOfRange {
        /// Index of the factor.
        factor: usize,
        /// The parameter index it uses.
        index: usize,
        /// Number of parameters of the chain.
        n_params: usize,
    },
    /// A factor refers to a joint that does not exist.
    #[error("factor {factor}: joint index {index} is out of range ({n_joints} joints)")]
    JointOutOfRange {
        /// Index of the factor.
        factor: usize,
        /// The joint index it uses.
        index: usize,
        /// Number of joints of the chain.
        n_joints: usize,
    },
    /// A parameter belongs to an element that does not exist.
    #[error("parameter {param}: element index {index} is out of range ({n_elements} elements)")]
    ElementOutOfRange {
        /// Parameter name.
        param: String,
        /// The element index it names.
        index: usize,
        /// Number of elements of the chain.
        n_elements: usize,
    },
    /// Two parameters, joints or elements share a name, so names would be ambiguous.
    #[error("duplicate {kind} name {name:?}")]
    DuplicateName {
        /// `parameter`, `joint` or `element`.
        kind: &'static str,
        /// The repeated name.
        name: String,
    },
}
