//! Rigid transforms as a rotation matrix and a translation: the little the chain needs.

/// A rigid transform `a_T_b`: the pose of frame b expressed in frame a.
///
/// `rotation[i][j]` is row i, column j of the 3 × 3 rotation matrix (row-major; column j is
/// b's j-th axis in a); `translation_m` is b's origin in a, m. `#[repr(C)]`: the C ABI's
/// `HapcalPose` has the same layout.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Pose {
    /// Rotation matrix, row-major.
    pub rotation: [[f64; 3]; 3],
    /// Translation, m.
    pub translation_m: [f64; 3],
}

impl Pose {
    /// The identity transform.
    pub const IDENTITY: Pose = Pose {
        rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        translation_m: [0.0; 3],
    };

    /// The rotation matrix of the quaternion `q = [w, x, y, z]`, normalised first (a
    /// measured or written quaternion whose norm is 1 up to rounding). The one conversion the
    /// runtime, `predict`'s errors and the targets of `compensate` share.
    pub fn rotation_of_quaternion(q: [f64; 4]) -> [[f64; 3]; 3] {
        let norm = libm::sqrt(q.iter().map(|v| v * v).sum::<f64>());
        let [w, x, y, z] = q.map(|v| v / norm);
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    }

    /// The composition `self · other` (`a_T_c = a_T_b · b_T_c`).
    #[inline]
    pub fn compose(&self, other: &Pose) -> Pose {
        let o = &other.rotation;
        let t = &other.translation_m;
        let mut out = Pose::IDENTITY;
        let rows = self.rotation.iter().zip(&self.translation_m);
        for ((out_row, out_t), (r, self_t)) in out
            .rotation
            .iter_mut()
            .zip(&mut out.translation_m)
            .zip(rows)
        {
            for (j, x) in out_row.iter_mut().enumerate() {
                *x = r[0] * o[0][j] + r[1] * o[1][j] + r[2] * o[2][j];
            }
            *out_t = self_t + r[0] * t[0] + r[1] * t[1] + r[2] * t[2];
        }
        out
    }

    /// [`Pose::compose`], with the rotation product skipped when `other`'s rotation is the
    /// identity (a URDF origin without `rpy`, a marker left at its default): the same result,
    /// a translation instead of 45 products and sums.
    #[cfg(feature = "std")]
    #[inline]
    pub(crate) fn compose_fast(&self, other: &Pose) -> Pose {
        if other.has_identity_rotation() {
            let t = self.rotate(&other.translation_m);
            let s = &self.translation_m;
            Pose {
                rotation: self.rotation,
                translation_m: [s[0] + t[0], s[1] + t[1], s[2] + t[2]],
            }
        } else {
            self.compose(other)
        }
    }

    /// Whether the rotation is exactly the identity (off the diagonal first: a general
    /// rotation fails at the first test).
    #[cfg(feature = "std")]
    #[inline(always)]
    pub(crate) fn has_identity_rotation(&self) -> bool {
        let r = &self.rotation;
        r[0][1] == 0.0
            && r[0][2] == 0.0
            && r[1][0] == 0.0
            && r[1][2] == 0.0
            && r[2][0] == 0.0
            && r[2][1] == 0.0
            && r[0][0] == 1.0
            && r[1][1] == 1.0
            && r[2][2] == 1.0
    }

    /// `self · R` with `R` a rotation about the coordinate axis after `I` and before `J`
    /// (x for `I, J = 1, 2`; y for 2, 0; z for 0, 1) by the angle of sine `s` and cosine `c`:
    /// columns I and J turn, the third column and the translation stay.
    #[inline]
    pub(crate) fn then_turn<const I: usize, const J: usize>(&mut self, s: f64, c: f64) {
        for row in &mut self.rotation {
            let (x, y) = (row[I], row[J]);
            row[I] = c * x + s * y;
            row[J] = -s * x + c * y;
        }
    }

    /// The inverse transform `b_T_a` (`Rᵀ`, `−Rᵀ·t`).
    #[inline]
    pub fn inverse(&self) -> Pose {
        let r = &self.rotation;
        let mut rotation = [[0.0; 3]; 3];
        for (i, row) in rotation.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = r[j][i];
            }
        }
        let t = self.inverse_rotate(&self.translation_m);
        Pose {
            rotation,
            translation_m: [-t[0], -t[1], -t[2]],
        }
    }

    /// `a` applied to a vector: `R · v` (no translation).
    #[inline]
    pub fn rotate(&self, v: &[f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        [
            r[0][0] * v[0] + r[0][1] * v[1] + r[0][2] * v[2],
            r[1][0] * v[0] + r[1][1] * v[1] + r[1][2] * v[2],
            r[2][0] * v[0] + r[2][1] * v[1] + r[2][2] * v[2],
        ]
    }

    /// `Rᵀ · v`: a vector of frame a expressed in frame b.
    #[inline]
    pub fn inverse_rotate(&self, v: &[f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        [
            r[0][0] * v[0] + r[1][0] * v[1] + r[2][0] * v[2],
            r[0][1] * v[0] + r[1][1] * v[1] + r[2][1] * v[2],
            r[0][2] * v[0] + r[1][2] * v[1] + r[2][2] * v[2],
        ]
    }

    /// `self · Rz(angle)` given `(sin, cos)` of the angle: columns 0 and 1 turn, column 2
    /// and the translation stay.
    #[inline]
    pub(crate) fn then_rot_z(&mut self, s: f64, c: f64) {
        self.then_turn::<0, 1>(s, c);
    }

    /// Rotation about x by `(s, c)`.
    pub(crate) fn rot_x(s: f64, c: f64) -> Pose {
        Pose {
            rotation: [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
            translation_m: [0.0; 3],
        }
    }

    /// Rotation about y by `(s, c)`.
    pub(crate) fn rot_y(s: f64, c: f64) -> Pose {
        Pose {
            rotation: [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
            translation_m: [0.0; 3],
        }
    }

    /// Rotation about z by `(s, c)`.
    pub(crate) fn rot_z(s: f64, c: f64) -> Pose {
        let mut p = Pose::IDENTITY;
        p.then_rot_z(s, c);
        p
    }

    /// Translation by `t`, m.
    pub(crate) fn translation(t: [f64; 3]) -> Pose {
        Pose {
            translation_m: t,
            ..Pose::IDENTITY
        }
    }
}

/// `a × b`.
#[inline]
pub(crate) fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
