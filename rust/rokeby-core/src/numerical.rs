//! Linear algebra, one home: sparse assembly, the sparse Cholesky (LLᵀ) and LU factorisations of
//! faer used by the geodesic heat method ([`crate::geometry::geodesic`], Crane et al. 2013), the shadow mesh
//! ([`crate::shadows::shadow_mesh`], Sorkine 2006) and the hole filling ([`crate::compositing::reconstruct`]), and the
//! small fixed-size dense Cholesky of the SH fits ([`crate::compositing::sh`]), together with the classification
//! of their failures:
//!
//! | failure                                        | error                                   |
//! |------------------------------------------------|-----------------------------------------|
//! | allocation refused                             | [`RokebyError::OutOfMemory`]            |
//! | more entries than 32-bit sparse indices hold   | [`RokebyError::OutOfMemory`]            |
//! | a triplet outside the matrix (indices were validated before: a bug) | [`RokebyError::Internal`] |
//! | a non-positive pivot (not positive definite), a structurally singular LU | [`RokebyError::Numerical`] |

use crate::error::{Result, RokebyError};
use faer::sparse::linalg::solvers::{Llt, Lu, SymbolicLlt};
use faer::sparse::linalg::{LltError, LuError};
use faer::sparse::{CreationError, FaerError, SparseColMat};
use faer::Side;

pub use faer::sparse::Triplet;

/// A sparse matrix of f64 with 32-bit indices (column-major).
pub type SparseMatrix = SparseColMat<u32, f64>;

fn generic_error(what: &str, e: FaerError) -> RokebyError {
    match e {
        FaerError::OutOfMemory => RokebyError::out_of_memory(what.to_string(), None, None),
        FaerError::IndexOverflow => RokebyError::OutOfMemory {
            what: what.to_string(),
            msg: "has more entries than 32-bit sparse indices can hold".into(),
        },
        _ => RokebyError::internal(format!("{what}: {e:?}")),
    }
}

/// The n×n sparse matrix of `triplets` (repeated entries are summed). `what` names the system in
/// errors. A triplet outside the matrix is an internal error: callers validate their indices.
pub fn assemble(n: usize, triplets: &[Triplet<u32, u32, f64>], what: &str) -> Result<SparseMatrix> {
    SparseColMat::try_new_from_triplets(n, n, triplets).map_err(|e| match e {
        CreationError::Generic(g) => generic_error(&format!("the {what} matrix"), g),
        CreationError::OutOfBounds { row, col } => RokebyError::internal(format!(
            "the {what} matrix: entry ({row}, {col}) is outside the {n}×{n} matrix"
        )),
    })
}

/// The symbolic part of a sparse Cholesky factorisation (fill-reducing ordering and elimination
/// tree) of a sparsity pattern: several matrices with one pattern share it.
#[derive(Clone)]
pub struct SymbolicCholesky {
    symbolic: SymbolicLlt<u32>,
}

impl SymbolicCholesky {
    /// The symbolic factorisation of the lower triangle of `pattern`.
    pub fn new(pattern: &SparseMatrix, what: &str) -> Result<Self> {
        let symbolic = SymbolicLlt::try_new(pattern.symbolic(), Side::Lower)
            .map_err(|e| generic_error(&format!("the {what} factorisation"), e))?;
        Ok(SymbolicCholesky { symbolic })
    }

    /// The numeric factorisation L Lᵀ of `m` (its lower triangle; the pattern given to
    /// [`SymbolicCholesky::new`]). A matrix that is not positive definite is a numerical failure.
    pub fn factor(&self, m: &SparseMatrix, what: &str) -> Result<Llt<u32, f64>> {
        Llt::try_new_with_symbolic(self.symbolic.clone(), m.as_ref(), Side::Lower)
            .map_err(|e| llt_error(what, e))
    }
}

fn llt_error(what: &str, e: LltError) -> RokebyError {
    match e {
        LltError::Numeric(n) => RokebyError::numerical(
            what.to_string(),
            format!("the system is not positive definite ({n:?})"),
        ),
        LltError::Generic(g) => generic_error(&format!("the {what} factorisation"), g),
    }
}

/// The sparse Cholesky factorisation of the symmetric positive definite `m` (lower triangle).
pub fn cholesky(m: &SparseMatrix, what: &str) -> Result<Llt<u32, f64>> {
    SymbolicCholesky::new(m, what)?.factor(m, what)
}

/// The sparse LU factorisation (partial pivoting) of the square `m`.
pub fn lu(m: &SparseMatrix, what: &str) -> Result<Lu<u32, f64>> {
    m.sp_lu().map_err(|e| match e {
        LuError::SymbolicSingular { index } => RokebyError::numerical(
            what.to_string(),
            format!("the system is singular (no pivot at step {index})"),
        ),
        LuError::Generic(g) => generic_error(&format!("the {what} factorisation"), g),
    })
}

/// The Cholesky factor L of a small symmetric positive definite N×N matrix (row-major, f64),
/// kept on the stack: the SH fits (N = 9) solve with it inside the active-set loop, where a
/// heap-allocated faer matrix per solve would cost more than the solve.
#[derive(Debug, Clone)]
pub struct DenseCholesky<const N: usize> {
    l: [[f64; N]; N],
}

impl<const N: usize> DenseCholesky<N> {
    /// L with L Lᵀ = `h` (only the lower triangle of `h` is read); `None` when a pivot is not
    /// positive (`h` is not positive definite, or has NaN).
    pub fn new(h: &[[f64; N]; N]) -> Option<Self> {
        let mut l = [[0.0; N]; N];
        for i in 0..N {
            for j in 0..=i {
                let mut s = h[i][j];
                for (a, b) in l[i][..j].iter().zip(&l[j][..j]) {
                    s -= a * b;
                }
                if i == j {
                    if s.is_nan() || s <= 0.0 {
                        return None;
                    }
                    l[i][i] = s.sqrt();
                } else {
                    l[i][j] = s / l[j][j];
                }
            }
        }
        Some(DenseCholesky { l })
    }

    /// H⁻¹ b by forward and back substitution.
    pub fn solve(&self, b: &[f64; N]) -> [f64; N] {
        let l = &self.l;
        let mut y = *b;
        for i in 0..N {
            for k in 0..i {
                y[i] -= l[i][k] * y[k];
            }
            y[i] /= l[i][i];
        }
        for i in (0..N).rev() {
            for k in i + 1..N {
                y[i] -= l[k][i] * y[k];
            }
            y[i] /= l[i][i];
        }
        y
    }
}

/// Solves the small dense system (the SH fits' active-set systems) M x = b (Gaussian elimination, partial pivoting). None if singular.
pub fn solve_dense(mut m: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let q = b.len();
    for col in 0..q {
        let piv = (col..q).max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))?;
        if m[piv][col].abs() < 1e-300 {
            return None;
        }
        m.swap(col, piv);
        b.swap(col, piv);
        for r in col + 1..q {
            let f = m[r][col] / m[col][col];
            // Row r minus f · row col: two rows of one matrix, one subscript.
            #[allow(clippy::needless_range_loop)]
            for k in col..q {
                m[r][k] -= f * m[col][k];
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = vec![0.0; q];
    for i in (0..q).rev() {
        let mut s = b[i];
        for k in i + 1..q {
            s -= m[i][k] * x[k];
        }
        x[i] = s / m[i][i];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::linalg::solvers::Solve;
    use faer::Mat;

    fn lower(n: usize, entries: &[(u32, u32, f64)]) -> SparseMatrix {
        let t: Vec<_> = entries
            .iter()
            .map(|&(i, j, v)| Triplet::new(i, j, v))
            .collect();
        assemble(n, &t, "test").unwrap()
    }

    #[test]
    fn cholesky_solves_a_positive_definite_system() {
        // [[4, 1], [1, 3]] x = [1, 2] → x = [1/11, 7/11].
        let m = lower(2, &[(0, 0, 4.0), (1, 0, 1.0), (1, 1, 3.0)]);
        let llt = cholesky(&m, "test").unwrap();
        let mut b = Mat::<f64>::zeros(2, 1);
        b[(0, 0)] = 1.0;
        b[(1, 0)] = 2.0;
        let x = llt.solve(&b);
        assert!((x[(0, 0)] - 1.0 / 11.0).abs() < 1e-12);
        assert!((x[(1, 0)] - 7.0 / 11.0).abs() < 1e-12);
    }

    #[test]
    fn an_indefinite_system_is_a_numerical_failure() {
        // [[1, 2], [2, 1]] has eigenvalues 3 and −1.
        let m = lower(2, &[(0, 0, 1.0), (1, 0, 2.0), (1, 1, 1.0)]);
        let e = cholesky(&m, "heat").unwrap_err();
        assert!(
            matches!(&e, RokebyError::Numerical { what, .. } if what == "heat"),
            "{e:?}"
        );
        assert!(e.to_string().contains("not positive definite"), "{e}");
    }

    #[test]
    fn a_singular_lu_is_a_numerical_failure() {
        // Column 1 is empty: structurally singular.
        let m = lower(2, &[(0, 0, 1.0), (1, 0, 1.0)]);
        let e = lu(&m, "hole filling").unwrap_err();
        assert!(matches!(e, RokebyError::Numerical { .. }), "{e:?}");
    }

    #[test]
    fn a_triplet_outside_the_matrix_is_an_internal_error() {
        let e = assemble(2, &[Triplet::new(5, 0, 1.0)], "test").unwrap_err();
        assert!(matches!(e, RokebyError::Internal(_)), "{e:?}");
        assert!(e.to_string().contains("please report"), "{e}");
    }

    #[test]
    fn dense_cholesky_solves_and_refuses_indefinite() {
        let h = [[4.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 2.0]];
        let c = DenseCholesky::new(&h).unwrap();
        let x = c.solve(&[1.0, 2.0, 3.0]);
        for i in 0..3 {
            let hx: f64 = (0..3).map(|j| h[i][j] * x[j]).sum();
            assert!((hx - [1.0, 2.0, 3.0][i]).abs() < 1e-12);
        }
        assert!(DenseCholesky::new(&[[1.0, 2.0], [2.0, 1.0]]).is_none());
        assert!(DenseCholesky::new(&[[f64::NAN]]).is_none());
    }
}
