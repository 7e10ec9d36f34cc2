//! A small 3×3 tensor: row-major components, outer products, traces, symmetric and
//! antisymmetric parts, deviators and norms.

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// A 3×3 tensor stored row-major: `t.0[i][j]` is the (i, j) component. Serialised as
/// a list of three rows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Tensor(pub [[f64; 3]; 3]);

impl Tensor {
    /// All components zero.
    pub const ZERO: Tensor = Tensor([[0.0; 3]; 3]);

    /// The identity restricted to the first `dims` axes (2: xy only).
    pub fn identity(dims: usize) -> Tensor {
        let mut t = Tensor::ZERO;
        for d in 0..dims.min(3) {
            t.0[d][d] = 1.0;
        }
        t
    }

    /// Adds `weight · a ⊗ b`, i.e. component (i, j) grows by `weight · a_i · b_j`.
    #[inline]
    pub fn add_outer(&mut self, a: DVec3, b: DVec3, weight: f64) {
        let (a, b) = (a.to_array(), b.to_array());
        for (row, ai) in self.0.iter_mut().zip(a) {
            let wa = weight * ai;
            for (x, bj) in row.iter_mut().zip(b) {
                *x += wa * bj;
            }
        }
    }

    /// Every component multiplied by `s`.
    pub fn scaled(self, s: f64) -> Tensor {
        let mut t = self;
        t.0.iter_mut().flatten().for_each(|x| *x *= s);
        t
    }

    /// Component-wise sum.
    pub fn plus(self, other: Tensor) -> Tensor {
        let mut t = self;
        for (x, y) in t.0.iter_mut().flatten().zip(other.0.iter().flatten()) {
            *x += y;
        }
        t
    }

    /// Component-wise difference.
    pub fn minus(self, other: Tensor) -> Tensor {
        self.plus(other.scaled(-1.0))
    }

    /// The transpose.
    pub fn transpose(self) -> Tensor {
        let mut t = Tensor::ZERO;
        for i in 0..3 {
            for j in 0..3 {
                t.0[i][j] = self.0[j][i];
            }
        }
        t
    }

    /// ½ (T + Tᵀ).
    pub fn symmetric_part(self) -> Tensor {
        self.plus(self.transpose()).scaled(0.5)
    }

    /// ½ (T − Tᵀ).
    pub fn antisymmetric_part(self) -> Tensor {
        self.minus(self.transpose()).scaled(0.5)
    }

    /// Sum of the first `dims` diagonal components.
    pub fn trace(&self, dims: usize) -> f64 {
        (0..dims.min(3)).map(|d| self.0[d][d]).sum()
    }

    /// T − (tr T / dims) I over the first `dims` axes: the deviator of a `dims`-D tensor.
    pub fn deviator(self, dims: usize) -> Tensor {
        let dims = dims.clamp(1, 3);
        self.minus(Tensor::identity(dims).scaled(self.trace(dims) / dims as f64))
    }

    /// Double contraction T : U = Σ T_ij U_ij.
    pub fn contract(&self, other: &Tensor) -> f64 {
        self.0
            .iter()
            .flatten()
            .zip(other.0.iter().flatten())
            .map(|(x, y)| x * y)
            .sum()
    }

    /// Frobenius norm √(T : T).
    pub fn norm(&self) -> f64 {
        self.contract(self).sqrt()
    }

    /// Whether every component is finite.
    pub fn is_finite(&self) -> bool {
        self.0.iter().flatten().all(|x| x.is_finite())
    }

    /// The inverse of the leading `dims` × `dims` block (other components zero), or
    /// `None` when that block is singular or badly conditioned: its determinant below
    /// `1e-12` times the `dims`-th power of its mean diagonal. Used for the symmetric,
    /// positive semi-definite second moments of grain positions.
    pub fn inverse_leading(&self, dims: usize) -> Option<Tensor> {
        let m = &self.0;
        let scale = self.trace(dims) / dims as f64;
        if !(scale > 0.0 && scale.is_finite()) {
            return None;
        }
        let mut inv = Tensor::ZERO;
        match dims {
            1 => inv.0[0][0] = 1.0 / m[0][0],
            2 => {
                let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
                if det.is_nan() || det <= 1e-12 * scale * scale {
                    return None;
                }
                inv.0[0][0] = m[1][1] / det;
                inv.0[0][1] = -m[0][1] / det;
                inv.0[1][0] = -m[1][0] / det;
                inv.0[1][1] = m[0][0] / det;
            }
            3 => {
                let c = |i: usize, j: usize| {
                    // Cofactor of (i, j) by cyclic indices.
                    let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
                    let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
                    m[i1][j1] * m[i2][j2] - m[i1][j2] * m[i2][j1]
                };
                let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
                if det.is_nan() || det <= 1e-12 * scale * scale * scale {
                    return None;
                }
                for i in 0..3 {
                    for j in 0..3 {
                        inv.0[i][j] = c(j, i) / det;
                    }
                }
            }
            _ => return None,
        }
        inv.is_finite().then_some(inv)
    }

    /// Matrix product T U.
    pub fn mul(&self, other: &Tensor) -> Tensor {
        let mut t = Tensor::ZERO;
        for i in 0..3 {
            for j in 0..3 {
                t.0[i][j] = (0..3).map(|k| self.0[i][k] * other.0[k][j]).sum();
            }
        }
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outer_product_is_row_force_column_branch() {
        let mut t = Tensor::ZERO;
        t.add_outer(DVec3::new(1.0, 2.0, 3.0), DVec3::new(4.0, 5.0, 6.0), 2.0);
        assert_eq!(t.0[0][1], 2.0 * 1.0 * 5.0);
        assert_eq!(t.0[2][0], 2.0 * 3.0 * 4.0);
        assert_eq!(t.trace(3), 2.0 * (4.0 + 10.0 + 18.0));
    }

    #[test]
    fn inverse_of_a_well_conditioned_block_and_none_for_a_singular_one() {
        let m = Tensor([[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]]);
        let inv = m.inverse_leading(3).unwrap();
        let id = m.mul(&inv);
        assert!(id.minus(Tensor::identity(3)).norm() < 1e-14);
        let m2 = Tensor([[2.0, 1.0, 0.0], [1.0, 3.0, 0.0], [0.0, 0.0, 0.0]]);
        let inv2 = m2.inverse_leading(2).unwrap();
        assert!(m2.mul(&inv2).minus(Tensor::identity(2)).norm() < 1e-14);
        let singular = Tensor([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 0.0]]);
        assert!(singular.inverse_leading(2).is_none());
        assert!(Tensor::ZERO.inverse_leading(3).is_none());
    }

    #[test]
    fn deviator_is_traceless() {
        let m = Tensor([[-3.0, 0.5, 0.0], [0.5, -1.0, 0.0], [0.0, 0.0, -2.0]]);
        assert!(m.deviator(3).trace(3).abs() < 1e-15);
        assert!(m.deviator(2).trace(2).abs() < 1e-15);
        assert_eq!(m.deviator(2).0[2][2], -2.0);
    }
}
