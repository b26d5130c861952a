//! The Newton system: a symmetric block-sparse matrix (3×3 blocks, CSR over vertices) with a
//! fixed pattern from the mesh topology plus a few extra blocks from contacts, and a
//! block-Jacobi preconditioned conjugate-gradient solver, warm-started.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// Symmetric block-sparse matrix. The pattern holds every block the elastic terms touch; blocks
/// outside it (self-contact pairs) go to `extra`.
#[derive(Debug, Clone, Default)]
pub struct BlockCsr {
    row_ptr: Vec<usize>,
    col: Vec<u32>,
    /// Block values, row after row.
    pub blocks: Vec<Matrix3<f64>>,
    diag: Vec<usize>,
    /// Blocks outside the pattern: (row, column, value), both triangles stored.
    pub extra: Vec<(u32, u32, Matrix3<f64>)>,
}

impl BlockCsr {
    /// A matrix for `n` vertices whose pattern holds the diagonal and every `(i, j)` of `pairs`
    /// (both orders).
    pub fn with_pattern(n: usize, pairs: impl IntoIterator<Item = (u32, u32)>) -> BlockCsr {
        let mut rows: Vec<Vec<u32>> = (0..n as u32).map(|i| vec![i]).collect();
        for (i, j) in pairs {
            if i != j {
                rows[i as usize].push(j);
                rows[j as usize].push(i);
            }
        }
        let mut row_ptr = Vec::with_capacity(n + 1);
        let mut col = Vec::new();
        let mut diag = Vec::with_capacity(n);
        row_ptr.push(0);
        for (i, r) in rows.iter_mut().enumerate() {
            r.sort_unstable();
            r.dedup();
            let start = col.len();
            col.extend_from_slice(r);
            diag.push(start + r.iter().position(|&c| c as usize == i).unwrap_or(0));
            row_ptr.push(col.len());
        }
        let nnz = col.len();
        BlockCsr {
            row_ptr,
            col,
            blocks: vec![Matrix3::zeros(); nnz],
            diag,
            extra: Vec::new(),
        }
    }

    /// Number of block rows.
    pub fn n(&self) -> usize {
        self.diag.len()
    }

    /// Number of stored blocks in the pattern.
    pub fn nnz_blocks(&self) -> usize {
        self.col.len()
    }

    /// Index of block (i, j) in [`BlockCsr::blocks`], if in the pattern.
    pub fn find(&self, i: u32, j: u32) -> Option<usize> {
        let (a, b) = (self.row_ptr[i as usize], self.row_ptr[i as usize + 1]);
        self.col[a..b].binary_search(&j).ok().map(|k| a + k)
    }

    /// Index of diagonal block i.
    pub fn diag_index(&self, i: u32) -> usize {
        self.diag[i as usize]
    }

    /// The block values (mutable) together with every row's diagonal slot.
    pub fn blocks_and_diag_mut(&mut self) -> (&mut [Matrix3<f64>], &[usize]) {
        (&mut self.blocks, &self.diag)
    }

    /// Zeroes all values and drops extra blocks.
    pub fn clear(&mut self) {
        self.blocks
            .par_iter_mut()
            .for_each(|b| *b = Matrix3::zeros());
        self.extra.clear();
    }

    /// Adds `m` to block (i, j): into the pattern when present, else to the extras.
    pub fn add(&mut self, i: u32, j: u32, m: &Matrix3<f64>) {
        match self.find(i, j) {
            Some(k) => self.blocks[k] += m,
            None => self.extra.push((i, j, *m)),
        }
    }

    /// A = Pᵀ A P for the map P that sends each vertex i to `master[i]` (with
    /// `master[master[i]] == master[i]`): every block (i, j) added to (master[i], master[j]);
    /// rows and columns of the vertices that follow another are left zero.
    pub fn fold(&mut self, master: &[u32]) {
        for i in 0..self.n() {
            for k in self.row_ptr[i]..self.row_ptr[i + 1] {
                let j = self.col[k] as usize;
                let (mi, mj) = (master[i], master[j]);
                if mi as usize == i && mj as usize == j {
                    continue;
                }
                let b = std::mem::replace(&mut self.blocks[k], Matrix3::zeros());
                self.add(mi, mj, &b);
            }
        }
        for e in &mut self.extra {
            e.0 = master[e.0 as usize];
            e.1 = master[e.1 as usize];
        }
    }

    /// y = A·x, skipping rows and columns where `free` is false.
    pub fn matvec(&self, x: &[Vector3<f64>], y: &mut [Vector3<f64>], free: &[bool]) {
        self.matvec_with(&self.blocks, x, y, free, 1);
    }

    /// y = A·x with the pattern's blocks given as `blocks` (f64 or f32) and the extras in f64;
    /// rows are shared among threads in runs of at least `min_rows` (`usize::MAX`: all on the
    /// calling thread).
    pub fn matvec_with<T>(
        &self,
        blocks: &[Matrix3<T>],
        x: &[Vector3<f64>],
        y: &mut [Vector3<f64>],
        free: &[bool],
        min_rows: usize,
    ) where
        T: nalgebra::RealField + Copy + Into<f64>,
    {
        for_each_entry(y, min_rows, |i, yi| {
            if !free[i] {
                *yi = Vector3::zeros();
                return;
            }
            let mut acc = Vector3::zeros();
            let row = self.row_ptr[i]..self.row_ptr[i + 1];
            for (b, &j) in blocks[row.clone()].iter().zip(&self.col[row]) {
                let j = j as usize;
                if free[j] {
                    let xj = &x[j];
                    for r in 0..3 {
                        acc[r] += b[(r, 0)].into() * xj[0]
                            + b[(r, 1)].into() * xj[1]
                            + b[(r, 2)].into() * xj[2];
                    }
                }
            }
            *yi = acc;
        });
        for (i, j, m) in &self.extra {
            let (i, j) = (*i as usize, *j as usize);
            if free[i] && free[j] {
                y[i] += m * x[j];
            }
        }
    }
}

/// Runs `f(i, &mut out[i])` for every entry, shared among rayon's threads in runs of at least
/// `min_len`, or in a plain loop on the calling thread when `min_len` is `usize::MAX`: even
/// an unsplit parallel pass costs rayon's bridge a few microseconds, and CG makes about ten
/// passes an iteration, each short on a small mesh.
fn for_each_entry<T: Send>(out: &mut [T], min_len: usize, f: impl Fn(usize, &mut T) + Sync) {
    if min_len == usize::MAX {
        out.iter_mut().enumerate().for_each(|(i, o)| f(i, o));
    } else {
        out.par_iter_mut()
            .with_min_len(min_len.max(1))
            .enumerate()
            .for_each(|(i, o)| f(i, o));
    }
}

/// Pattern size (blocks) from which conjugate gradients multiply with single-precision blocks
/// (≈ 10K vertices: 4.5 MB of f32 blocks, beyond a core's L2).
pub const SINGLE_PRECISION_FROM_BLOCKS: usize = 130_000;

/// Rows per range of [`UpperF32`]'s product: a fixed size, so that the order of every sum, and
/// so the result, does not depend on the thread count.
const UPPER_RANGE_ROWS: usize = 2048;

/// The upper triangle (diagonal included) of a [`BlockCsr`]'s pattern in single precision:
/// a quarter of the memory a product reads from the full f64 pattern. Rows are taken in ranges
/// of [`UPPER_RANGE_ROWS`], one range per task: block (i, j) adds to row i and, transposed, to
/// row j, straight when j lies in the range (rows are ordered along the mesh, so most do), else
/// through the range's spill list, added after all ranges in order.
#[derive(Debug, Clone, Default)]
struct UpperF32 {
    /// Per row, where its blocks start in `col` and `blocks` (n + 1 entries).
    row_ptr: Vec<usize>,
    col: Vec<u32>,
    /// For each upper block, its index in the full matrix's blocks.
    source: Vec<usize>,
    blocks: Vec<Matrix3<f32>>,
    /// The full pattern this was built for (row pointers and columns' count).
    pattern: (usize, usize),
    /// Per range, its spills of the last product.
    spills: Vec<Vec<(u32, Vector3<f64>)>>,
}

impl UpperF32 {
    /// Takes `a`'s current values (and its pattern, when it changed).
    fn update(&mut self, a: &BlockCsr) {
        if self.pattern != (a.n(), a.nnz_blocks()) || self.row_ptr.len() != a.n() + 1 {
            self.row_ptr.clear();
            self.col.clear();
            self.source.clear();
            self.row_ptr.push(0);
            for i in 0..a.n() {
                for k in a.row_ptr[i]..a.row_ptr[i + 1] {
                    if a.col[k] as usize >= i {
                        self.col.push(a.col[k]);
                        self.source.push(k);
                    }
                }
                self.row_ptr.push(self.col.len());
            }
            self.pattern = (a.n(), a.nnz_blocks());
            self.spills = vec![Vec::new(); a.n().div_ceil(UPPER_RANGE_ROWS)];
        }
        self.blocks.resize(self.source.len(), Matrix3::zeros());
        self.blocks
            .par_iter_mut()
            .zip(self.source.par_iter())
            .for_each(|(b, &k)| *b = a.blocks[k].cast::<f32>());
    }

    /// y = A·x, skipping rows and columns where `free` is false; `a` gives the extra blocks.
    fn matvec(&mut self, a: &BlockCsr, x: &[Vector3<f64>], y: &mut [Vector3<f64>], free: &[bool]) {
        let all_free = free.iter().all(|f| *f);
        let (row_ptr, col, blocks) = (&self.row_ptr, &self.col, &self.blocks);
        y.par_chunks_mut(UPPER_RANGE_ROWS)
            .zip(self.spills.par_iter_mut())
            .enumerate()
            .for_each(|(r, (ys, spill))| {
                let first = r * UPPER_RANGE_ROWS;
                let end = first + ys.len();
                spill.clear();
                ys.iter_mut().for_each(|v| *v = Vector3::zeros());
                for i in first..end {
                    if !all_free && !free[i] {
                        continue;
                    }
                    let xi = x[i];
                    let mut acc = Vector3::zeros();
                    for k in row_ptr[i]..row_ptr[i + 1] {
                        let j = col[k] as usize;
                        if !all_free && !free[j] {
                            continue;
                        }
                        let b: Matrix3<f64> = blocks[k].cast::<f64>();
                        acc += b * x[j];
                        if j == i {
                            continue;
                        }
                        let t = b.tr_mul(&xi);
                        if j < end {
                            ys[j - first] += t;
                        } else {
                            spill.push((j as u32, t));
                        }
                    }
                    ys[i - first] += acc;
                }
            });
        for spill in &self.spills {
            for (j, t) in spill {
                y[*j as usize] += t;
            }
        }
        for (i, j, m) in &a.extra {
            let (i, j) = (*i as usize, *j as usize);
            if free[i] && free[j] {
                y[i] += m * x[j];
            }
        }
        if !all_free {
            for (yi, f) in y.iter_mut().zip(free) {
                if !f {
                    *yi = Vector3::zeros();
                }
            }
        }
    }
}

/// Outcome of a linear solve.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CgStats {
    /// Iterations run.
    pub iterations: usize,
    /// Final relative residual ‖b − A·x‖ / ‖b‖.
    pub relative_residual: f64,
}

/// Reusable buffers of the conjugate-gradient solver.
#[derive(Debug, Clone, Default)]
pub struct Pcg {
    bufs: CgBuffers,
    inv_diag: Vec<Matrix3<f64>>,
}

#[derive(Debug, Clone, Default)]
struct CgBuffers {
    /// Shortest run of vectors' entries a thread takes in the solve's passes (`usize::MAX`:
    /// every pass on the calling thread; see [`Pcg::set_single_threaded`]).
    min_len: usize,
    /// Single-precision copy of the matrix's upper triangle for the products.
    upper32: UpperF32,
    r: Vec<Vector3<f64>>,
    z: Vec<Vector3<f64>>,
    p: Vec<Vector3<f64>>,
    ap: Vec<Vector3<f64>>,
}

fn dot(a: &[Vector3<f64>], b: &[Vector3<f64>], min_len: usize) -> f64 {
    super::reduce::dot(a, b, min_len)
}

impl CgBuffers {
    /// Preconditioned conjugate gradients on the free vertices, warm-started from `x`;
    /// `precondition(r, z)` applies the preconditioner.
    #[allow(clippy::too_many_arguments)]
    fn run(
        &mut self,
        a: &BlockCsr,
        b: &[Vector3<f64>],
        x: &mut [Vector3<f64>],
        free: &[bool],
        mut precondition: impl FnMut(&[Vector3<f64>], &mut [Vector3<f64>], usize),
        rel_tol: f64,
        max_iters: usize,
    ) -> CgStats {
        let n = a.n();
        let ml = self.min_len.max(1);
        for buf in [&mut self.r, &mut self.z, &mut self.p, &mut self.ap] {
            buf.resize(n, Vector3::zeros());
        }
        for (xi, f) in x.iter_mut().zip(free) {
            if !f {
                *xi = Vector3::zeros();
            }
        }
        let b_norm = dot(b, b, ml).sqrt();
        if b_norm == 0.0 {
            x.iter_mut().for_each(|v| *v = Vector3::zeros());
            return CgStats::default();
        }
        // Single-precision products only where the matrix outgrows the caches; below that
        // the conversion costs more than the bandwidth it saves.
        let single = a.nnz_blocks() >= SINGLE_PRECISION_FROM_BLOCKS;
        if single {
            self.upper32.update(a);
        }
        a.matvec_with(&a.blocks, x, &mut self.ap, free, ml);
        let ap = &self.ap;
        for_each_entry(&mut self.r, ml, |i, r| {
            *r = if free[i] {
                b[i] - ap[i]
            } else {
                Vector3::zeros()
            };
        });
        precondition(&self.r, &mut self.z, ml);
        self.p.copy_from_slice(&self.z);
        let mut rz = dot(&self.r, &self.z, ml);
        let mut res = dot(&self.r, &self.r, ml).sqrt() / b_norm;
        let mut it = 0;
        while it < max_iters && res > rel_tol {
            if single {
                self.upper32.matvec(a, &self.p, &mut self.ap, free);
            } else {
                a.matvec_with(&a.blocks, &self.p, &mut self.ap, free, ml);
            }
            let pap = dot(&self.p, &self.ap, ml);
            if pap.is_nan() || pap <= 0.0 {
                break;
            }
            let alpha = rz / pap;
            let (p, ap) = (&self.p, &self.ap);
            for_each_entry(x, ml, |i, xi| *xi += p[i] * alpha);
            for_each_entry(&mut self.r, ml, |i, ri| *ri -= ap[i] * alpha);
            precondition(&self.r, &mut self.z, ml);
            let rz_new = dot(&self.r, &self.z, ml);
            let beta = rz_new / rz;
            rz = rz_new;
            let z = &self.z;
            for_each_entry(&mut self.p, ml, |i, pi| *pi = z[i] + *pi * beta);
            res = dot(&self.r, &self.r, ml).sqrt() / b_norm;
            it += 1;
        }
        CgStats {
            iterations: it,
            relative_residual: res,
        }
    }
}

/// z = D⁻¹ r with the inverted diagonal blocks `inv`.
fn apply_jacobi(inv: &[Matrix3<f64>], r: &[Vector3<f64>], z: &mut [Vector3<f64>], ml: usize) {
    for_each_entry(z, ml, |i, zi| *zi = inv[i] * r[i]);
}

impl Pcg {
    /// Runs every pass of later solves on the calling thread (`true`) or shares them among
    /// rayon's threads (`false`, the default). On small meshes the hand-offs cost more than
    /// the passes.
    pub fn set_single_threaded(&mut self, single: bool) {
        self.bufs.min_len = if single { usize::MAX } else { 1 };
    }

    /// The inverse of each free vertex's 3×3 diagonal block (plus extra diagonal terms).
    fn update_jacobi(&mut self, a: &BlockCsr, free: &[bool]) {
        let n = a.n();
        self.inv_diag.resize(n, Matrix3::zeros());
        let mut diag: Vec<Matrix3<f64>> =
            (0..n).map(|i| a.blocks[a.diag_index(i as u32)]).collect();
        for (i, j, m) in &a.extra {
            if i == j {
                diag[*i as usize] += m;
            }
        }
        self.inv_diag
            .par_iter_mut()
            .zip(diag.par_iter())
            .enumerate()
            .for_each(|(i, (inv, d))| {
                *inv = if free[i] {
                    d.try_inverse().unwrap_or_else(|| {
                        Matrix3::from_diagonal(&d.diagonal().map(|v| {
                            if v.abs() > 0.0 {
                                1.0 / v
                            } else {
                                0.0
                            }
                        }))
                    })
                } else {
                    Matrix3::zeros()
                };
            });
    }

    /// Solves A·x = b for the free vertices, starting from the given `x` (warm start), with a
    /// block-Jacobi preconditioner, to `rel_tol` or `max_iters`.
    pub fn solve(
        &mut self,
        a: &BlockCsr,
        b: &[Vector3<f64>],
        x: &mut [Vector3<f64>],
        free: &[bool],
        rel_tol: f64,
        max_iters: usize,
    ) -> CgStats {
        self.update_jacobi(a, free);
        let inv = &self.inv_diag;
        let jacobi =
            |r: &[Vector3<f64>], z: &mut [Vector3<f64>], ml: usize| apply_jacobi(inv, r, z, ml);
        self.bufs.run(a, b, x, free, jacobi, rel_tol, max_iters)
    }

    /// As [`Pcg::solve`], preconditioned by block-Jacobi plus the two-level coarse correction
    /// `coarse` (factored for an earlier or the current matrix).
    #[allow(clippy::too_many_arguments)]
    pub fn solve_two_level(
        &mut self,
        a: &BlockCsr,
        b: &[Vector3<f64>],
        x: &mut [Vector3<f64>],
        free: &[bool],
        coarse: &mut TwoLevel,
        rel_tol: f64,
        max_iters: usize,
    ) -> CgStats {
        self.update_jacobi(a, free);
        let inv = &self.inv_diag;
        self.bufs.run(
            a,
            b,
            x,
            free,
            |r, z, ml| {
                apply_jacobi(inv, r, z, ml);
                coarse.add_correction(r, z, free);
            },
            rel_tol,
            max_iters,
        )
    }

    /// As [`Pcg::solve`], preconditioned by a Cholesky factor of an earlier matrix.
    #[allow(clippy::too_many_arguments)]
    pub fn solve_with_factor(
        &mut self,
        a: &BlockCsr,
        b: &[Vector3<f64>],
        x: &mut [Vector3<f64>],
        free: &[bool],
        pre: &mut CholeskyPreconditioner,
        rel_tol: f64,
        max_iters: usize,
    ) -> CgStats {
        self.bufs.run(
            a,
            b,
            x,
            free,
            |r, z, _| pre.apply(r, z, free),
            rel_tol,
            max_iters,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fold_is_the_projection_onto_the_welded_unknowns() {
        // A 5-vertex chain with an extra block; vertices 3 and 4 follow 1 and 0.
        let n = 5;
        let pairs = [(0, 1), (1, 2), (2, 3), (3, 4)];
        let master = [0u32, 1, 2, 1, 0];
        let folded = pairs
            .iter()
            .map(|&(i, j)| (master[i as usize], master[j as usize]));
        let mut a = BlockCsr::with_pattern(n, pairs.iter().copied().chain(folded));
        let block = |i: u32, j: u32| {
            Matrix3::from_fn(|r, c| 1.0 + (i * 7 + j * 3) as f64 + (r * 3 + c) as f64 * 0.1)
        };
        let mut dense = vec![vec![Matrix3::zeros(); n]; n];
        for i in 0..n as u32 {
            a.add(i, i, &block(i, i));
            dense[i as usize][i as usize] += block(i, i);
        }
        for &(i, j) in pairs.iter().chain([(4u32, 2u32)].iter()) {
            a.add(i, j, &block(i, j));
            a.add(j, i, &block(i, j).transpose());
            dense[i as usize][j as usize] += block(i, j);
            dense[j as usize][i as usize] += block(i, j).transpose();
        }
        a.fold(&master);
        // Pᵀ A P: every block (i, j) summed into (master i, master j).
        let mut want = vec![vec![Matrix3::zeros(); n]; n];
        for i in 0..n {
            for j in 0..n {
                want[master[i] as usize][master[j] as usize] += dense[i][j];
            }
        }
        let mut got = vec![vec![Matrix3::zeros(); n]; n];
        for i in 0..n as u32 {
            for j in 0..n as u32 {
                if let Some(k) = a.find(i, j) {
                    got[i as usize][j as usize] += a.blocks[k];
                }
            }
        }
        for (i, j, m) in &a.extra {
            got[*i as usize][*j as usize] += m;
        }
        for i in 0..n {
            for j in 0..n {
                assert!(
                    (got[i][j] - want[i][j]).abs().max() < 1e-12,
                    "block ({i}, {j}): {} against {}",
                    got[i][j],
                    want[i][j]
                );
            }
        }
    }

    /// A 1D chain of `n` vertices: springs `k` between neighbours plus `mass` on the diagonal.
    fn chain(n: u32, k: &Matrix3<f64>, mass: f64) -> BlockCsr {
        let mut a = BlockCsr::with_pattern(n as usize, (0..n - 1).map(|i| (i, i + 1)));
        for i in 0..n - 1 {
            a.add(i, i, k);
            a.add(i + 1, i + 1, k);
            a.add(i, i + 1, &-k);
            a.add(i + 1, i, &-k);
        }
        for i in 0..n {
            a.add(i, i, &(Matrix3::identity() * mass));
        }
        a
    }

    #[test]
    fn single_precision_products_of_a_large_matrix_still_solve_to_tolerance() {
        // A chain long enough for the f32 path; the true (f64) residual must meet the tolerance
        // up to the rounding of the blocks.
        let n = (SINGLE_PRECISION_FROM_BLOCKS / 3 + 10) as u32;
        let k = Matrix3::new(2.0, 0.3, 0.0, 0.3, 1.0, 0.1, 0.0, 0.1, 1.5);
        let a = chain(n, &k, 0.7);
        assert!(a.nnz_blocks() >= SINGLE_PRECISION_FROM_BLOCKS);
        let free = vec![true; n as usize];
        let b: Vec<Vector3<f64>> = (0..n)
            .map(|i| Vector3::new((i as f64 * 0.01).sin(), 1.0, (i % 7) as f64))
            .collect();
        let mut x = vec![Vector3::zeros(); n as usize];
        let stats = Pcg::default().solve(&a, &b, &mut x, &free, 1e-6, 2000);
        assert!(stats.relative_residual <= 1e-6, "{stats:?}");
        let mut ax = vec![Vector3::zeros(); n as usize];
        a.matvec(&x, &mut ax, &free);
        let r: f64 = ax
            .iter()
            .zip(&b)
            .map(|(p, q)| (p - q).norm_squared())
            .sum::<f64>()
            .sqrt();
        let bn: f64 = b.iter().map(|q| q.norm_squared()).sum::<f64>().sqrt();
        assert!(r / bn < 1e-5, "true relative residual {:.2e}", r / bn);
        // And the single-precision product of the upper triangle is the f64 one to single
        // precision, with the same bits on one thread and on three (pinned vertices skipped).
        let mut free = free;
        free[7] = false;
        free[n as usize / 2] = false;
        let mut upper = UpperF32::default();
        upper.update(&a);
        let on = |threads: usize, upper: &mut UpperF32| {
            let mut y = vec![Vector3::zeros(); n as usize];
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool")
                .install(|| upper.matvec(&a, &b, &mut y, &free));
            y
        };
        let (y1, y3) = (on(1, &mut upper), on(3, &mut upper));
        assert_eq!(y1, y3);
        a.matvec(&b, &mut ax, &free);
        for (p, q) in y1.iter().zip(&ax) {
            assert!((p - q).norm() <= 1e-6 * (1.0 + q.norm()), "{p:?} vs {q:?}");
        }
        assert_eq!(y1[7], Vector3::zeros());
    }

    /// A k×k grid of vertices with anisotropic springs to the right and up neighbours (stiff
    /// against a small mass: the ill-conditioned, membrane-dominated case), numbered row by
    /// row.
    fn grid(k: u32, stiffness: f64, mass: f64) -> BlockCsr {
        let id = |x: u32, y: u32| y * k + x;
        let mut pairs = Vec::new();
        for y in 0..k {
            for x in 0..k {
                if x + 1 < k {
                    pairs.push((id(x, y), id(x + 1, y)));
                }
                if y + 1 < k {
                    pairs.push((id(x, y), id(x, y + 1)));
                }
            }
        }
        let mut a = BlockCsr::with_pattern((k * k) as usize, pairs.iter().copied());
        let m = Matrix3::from_diagonal(&Vector3::new(1.0, 0.5, 0.2)) * stiffness;
        for (i, j) in pairs {
            a.add(i, i, &m);
            a.add(j, j, &m);
            a.add(i, j, &-m);
            a.add(j, i, &-m);
        }
        for i in 0..k * k {
            a.add(i, i, &(Matrix3::identity() * mass));
        }
        a
    }

    #[test]
    fn two_level_pcg_solves_with_fewer_iterations_than_block_jacobi() {
        let k = 40u32;
        let n = (k * k) as usize;
        let mut a = grid(k, 1e4, 1.0);
        // A contact-like coupling outside the pattern, and fixed vertices (a pinned corner).
        let c = Matrix3::identity() * 50.0;
        a.add(5, 1500, &-c);
        a.add(1500, 5, &-c);
        a.add(5, 5, &c);
        a.add(1500, 1500, &c);
        let mut free = vec![true; n];
        for f in free.iter_mut().take(3) {
            *f = false;
        }
        let truth: Vec<Vector3<f64>> = (0..n)
            .map(|i| {
                if free[i] {
                    let (x, y) = ((i % k as usize) as f64, (i / k as usize) as f64);
                    Vector3::new((0.1 * x).sin(), (0.07 * y).cos(), 0.01 * x * y)
                } else {
                    Vector3::zeros()
                }
            })
            .collect();
        let mut b = vec![Vector3::zeros(); n];
        a.matvec(&truth, &mut b, &free);
        let mut x = vec![Vector3::zeros(); n];
        let jacobi = Pcg::default().solve(&a, &b, &mut x, &free, 1e-8, 5000);
        let mut coarse = TwoLevel::new(&a, 16).expect("coarse analysis");
        assert_eq!(coarse.num_aggregates(), n / 16);
        assert!(coarse.factorize(&a, &free));
        let mut x = vec![Vector3::zeros(); n];
        let two = Pcg::default().solve_two_level(&a, &b, &mut x, &free, &mut coarse, 1e-8, 5000);
        assert!(two.relative_residual <= 1e-8, "{two:?}");
        let err = x
            .iter()
            .zip(&truth)
            .map(|(p, q)| (p - q).norm())
            .fold(0.0, f64::max);
        assert!(err < 1e-5, "error {err}");
        assert!(x[..3].iter().all(|v| *v == Vector3::zeros()));
        assert!(
            2 * two.iterations < jacobi.iterations,
            "two-level {} vs block-Jacobi {} iterations",
            two.iterations,
            jacobi.iterations
        );
        // Aggregates made only of fixed vertices are held, not singular.
        let mut free = vec![true; n];
        free[..32].iter_mut().for_each(|f| *f = false);
        assert!(coarse.factorize(&a, &free));
    }

    #[test]
    fn pcg_solves_a_spd_system_with_extras_and_fixed_rows() {
        // A 1D chain Laplacian + mass, with one long-range extra coupling, vertex 0 fixed.
        let n = 50u32;
        let mut a = chain(
            n,
            &Matrix3::from_diagonal(&Vector3::new(1.0, 2.0, 3.0)),
            0.1,
        );
        let c = Matrix3::identity() * 0.5;
        a.add(3, 40, &-c);
        a.add(40, 3, &-c);
        a.add(3, 3, &c);
        a.add(40, 40, &c);
        assert_eq!(a.extra.len(), 2);
        let mut free = vec![true; n as usize];
        free[0] = false;
        let truth: Vec<Vector3<f64>> = (0..n)
            .map(|i| {
                if i == 0 {
                    Vector3::zeros()
                } else {
                    Vector3::new(i as f64, 1.0, -0.5 * i as f64)
                }
            })
            .collect();
        let mut b = vec![Vector3::zeros(); n as usize];
        a.matvec(&truth, &mut b, &free);
        let mut x = vec![Vector3::zeros(); n as usize];
        let stats = Pcg::default().solve(&a, &b, &mut x, &free, 1e-12, 1000);
        assert!(stats.relative_residual <= 1e-12, "{stats:?}");
        let err = x
            .iter()
            .zip(&truth)
            .map(|(p, q)| (p - q).norm())
            .fold(0.0, f64::max);
        assert!(err < 1e-8, "error {err}");
        // Warm start from the solution: no iteration needed.
        let stats = Pcg::default().solve(&a, &b, &mut x, &free, 1e-10, 1000);
        assert_eq!(stats.iterations, 0);
        // With a Cholesky factor of the pattern part (the long-range extra is left out of the
        // factor), PCG converges in a handful of iterations.
        let mut pre = CholeskyPreconditioner::new(&a).expect("symbolic");
        assert!(pre.factorize(&a, &free));
        let mut x = vec![Vector3::zeros(); n as usize];
        let stats = Pcg::default().solve_with_factor(&a, &b, &mut x, &free, &mut pre, 1e-12, 1000);
        assert!(
            stats.relative_residual <= 1e-12 && stats.iterations <= 8,
            "{stats:?}"
        );
        let err = x
            .iter()
            .zip(&truth)
            .map(|(p, q)| (p - q).norm())
            .fold(0.0, f64::max);
        assert!(err < 1e-8, "error {err}");
    }
}

/// A sparse Cholesky factorisation (faer, symbolic analysis done once for the pattern) of the
/// matrix's pattern part, used as a preconditioner: refreshed only when the conjugate-gradient
/// iterations grow, so one factorisation serves many Newton iterations and steps. Off-pattern
/// contact blocks are left out of the factor (PCG still sees the true matrix); fixed vertices
/// become identity rows.
#[derive(Clone)]
pub struct CholeskyPreconditioner {
    symbolic: faer::sparse::SymbolicSparseColMat<usize>,
    llt_symbolic: std::sync::Arc<faer::sparse::linalg::cholesky::SymbolicCholesky<usize>>,
    /// Per pattern block k = (I, J) with I ≥ J: the value slot of each of its 9 scalars (row
    /// a, column b, column-major), or usize::MAX above the diagonal of a diagonal block.
    slots: Vec<(usize, [usize; 9])>,
    values: Vec<f64>,
    /// The factor's values, kept between factorisations (a stiff cloth's factor is hundreds
    /// of megabytes: allocated afresh each time, most of its cost was the pages' first touch).
    factor: Vec<f64>,
    factored: bool,
    /// The factorisation's and the solve's scratch memory, kept likewise.
    scratch: Scratch,
    work: Vec<f64>,
}

/// Scratch memory of faer's factorisation and solves, allocated on first use for the
/// parallelism then in force (a clone starts without).
#[derive(Default)]
struct Scratch {
    factorize: Option<(faer::Par, faer::dyn_stack::MemBuffer)>,
    solve: Option<(faer::Par, faer::dyn_stack::MemBuffer)>,
}

/// `slot`'s buffer when it was made for `par`, else a new one of `req(par)` (`None`: out of
/// memory).
fn scratch_for(
    slot: &mut Option<(faer::Par, faer::dyn_stack::MemBuffer)>,
    par: faer::Par,
    req: impl FnOnce(faer::Par) -> faer::dyn_stack::StackReq,
) -> Option<&mut faer::dyn_stack::MemBuffer> {
    if slot.as_ref().is_none_or(|(p, _)| *p != par) {
        *slot = Some((par, faer::dyn_stack::MemBuffer::try_new(req(par)).ok()?));
    }
    slot.as_mut().map(|(_, b)| b)
}

impl Clone for Scratch {
    fn clone(&self) -> Self {
        Scratch::default()
    }
}

impl std::fmt::Debug for CholeskyPreconditioner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CholeskyPreconditioner")
            .field("nnz", &self.values.len())
            .field("factored", &self.factored)
            .finish()
    }
}

impl CholeskyPreconditioner {
    /// Analyses the lower triangle of `a`'s pattern (fill-reducing ordering, symbolic factor).
    pub fn new(a: &BlockCsr) -> Option<CholeskyPreconditioner> {
        let n = a.n();
        // Column 3J + b holds rows 3I + a ≥ 3J + b for every pattern block (I, J), I ≥ J.
        // The pattern is symmetric, so block column J's rows I ≥ J are row J's columns ≥ J.
        let mut col_ptr = vec![0usize; 3 * n + 1];
        let mut row_idx = Vec::new();
        let mut slot_of: Vec<(usize, [usize; 9])> = Vec::new();
        let mut pending: Vec<(usize, usize, usize)> = Vec::new(); // (block k, a, b) per value
        for j in 0..n {
            let blocks: Vec<(usize, usize)> = (a.row_ptr[j]..a.row_ptr[j + 1])
                .filter(|&k| a.col[k] as usize >= j)
                .map(|k| (a.col[k] as usize, k))
                .collect();
            for b in 0..3 {
                for &(i, k) in &blocks {
                    for r in 0..3 {
                        if i == j && r < b {
                            continue;
                        }
                        row_idx.push(3 * i + r);
                        pending.push((k, r, b));
                    }
                }
                col_ptr[3 * j + b + 1] = row_idx.len();
            }
        }
        let mut map: std::collections::HashMap<usize, [usize; 9]> =
            std::collections::HashMap::new();
        for (slot, (k, r, b)) in pending.into_iter().enumerate() {
            map.entry(k).or_insert([usize::MAX; 9])[3 * b + r] = slot;
        }
        slot_of.extend(map);
        slot_of.sort_unstable_by_key(|(k, _)| *k);
        let nnz = row_idx.len();
        let symbolic =
            faer::sparse::SymbolicSparseColMat::new_checked(3 * n, 3 * n, col_ptr, None, row_idx);
        let llt_symbolic = faer::sparse::linalg::cholesky::factorize_symbolic_cholesky(
            symbolic.as_ref(),
            faer::Side::Lower,
            Default::default(),
            Default::default(),
        )
        .ok()?;
        Some(CholeskyPreconditioner {
            symbolic,
            llt_symbolic: std::sync::Arc::new(llt_symbolic),
            slots: slot_of,
            values: vec![0.0; nnz],
            factor: Vec::new(),
            factored: false,
            scratch: Scratch::default(),
            work: vec![0.0; 3 * n],
        })
    }

    /// Drops the factor: the next solve factorises again, as a new preconditioner would.
    pub fn forget(&mut self) {
        self.factored = false;
    }

    /// Whether a factor is available.
    pub fn is_factored(&self) -> bool {
        self.factored
    }

    /// Factorises the current values of `a` (fixed vertices as identity). Returns false (and
    /// keeps no factor) when the matrix is not numerically positive definite.
    pub fn factorize(&mut self, a: &BlockCsr, free: &[bool]) -> bool {
        let rows: Vec<usize> = (0..a.n())
            .flat_map(|i| std::iter::repeat_n(i, a.row_ptr[i + 1] - a.row_ptr[i]))
            .collect();
        for (k, slots) in &self.slots {
            // Pattern block k sits at (row j, column i) with i ≥ j: the factor's block (i, j) is
            // its transpose.
            let (j, i) = (rows[*k], a.col[*k] as usize);
            let m = a.blocks[*k].transpose();
            for b in 0..3 {
                for r in 0..3 {
                    let s = slots[3 * b + r];
                    if s == usize::MAX {
                        continue;
                    }
                    self.values[s] = if free[i] && free[j] {
                        m[(r, b)]
                    } else if i == j && r == b {
                        1.0
                    } else {
                        0.0
                    };
                }
            }
        }
        let mat = faer::sparse::SparseColMatRef::new(self.symbolic.as_ref(), &self.values);
        // As faer's `Llt::try_new_with_symbolic` does, into the kept memory: the factor's
        // values start from zero.
        let symbolic = &self.llt_symbolic;
        let par = faer::get_global_parallelism();
        self.factored = false;
        self.factor.clear();
        let len = symbolic.len_val();
        if self.factor.try_reserve_exact(len).is_err() {
            return false;
        }
        self.factor.resize(len, 0.0);
        let Some(scratch) = scratch_for(&mut self.scratch.factorize, par, |par| {
            symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default())
        }) else {
            return false;
        };
        self.factored = symbolic
            .factorize_numeric_llt::<f64>(
                &mut self.factor,
                mat,
                faer::Side::Lower,
                Default::default(),
                par,
                faer::dyn_stack::MemStack::new(scratch),
                Default::default(),
            )
            .is_ok();
        self.factored
    }

    /// z = L⁻ᵀL⁻¹ r (zero on fixed vertices).
    pub fn apply(&mut self, r: &[Vector3<f64>], z: &mut [Vector3<f64>], free: &[bool]) {
        if !self.factored {
            z.copy_from_slice(r);
            return;
        }
        for (i, v) in r.iter().enumerate() {
            self.work[3 * i..3 * i + 3].copy_from_slice(v.as_slice());
        }
        let n = self.work.len();
        let symbolic = &self.llt_symbolic;
        let par = faer::get_global_parallelism();
        let Some(scratch) = scratch_for(&mut self.scratch.solve, par, |par| {
            symbolic.solve_in_place_scratch::<f64>(1, par)
        }) else {
            // Out of memory for the solve: no preconditioning this time.
            z.copy_from_slice(r);
            return;
        };
        faer::sparse::linalg::cholesky::LltRef::new(symbolic, &self.factor)
            .solve_in_place_with_conj(
                faer::Conj::No,
                faer::MatMut::from_column_major_slice_mut(&mut self.work, n, 1),
                par,
                faer::dyn_stack::MemStack::new(scratch),
            );
        for (i, zi) in z.iter_mut().enumerate() {
            *zi = if free[i] {
                Vector3::new(self.work[3 * i], self.work[3 * i + 1], self.work[3 * i + 2])
            } else {
                Vector3::zeros()
            };
        }
    }
}

#[cfg(test)]
mod cholesky_tests {
    use super::*;

    #[test]
    fn cholesky_factor_of_the_matrix_itself_solves_in_one_iteration() {
        for n in [30u32, 3000] {
            factor_solves(n);
        }
    }

    fn factor_solves(n: u32) {
        // Random SPD block matrix on a ring with full (non-symmetric) 3×3 off-diagonal blocks.
        let mut seed = 1u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64) / ((1u64 << 53) as f64) - 0.5
        };
        let pairs: Vec<(u32, u32)> = (0..n)
            .map(|i| (i, (i + 1) % n))
            .chain((0..n).map(|i| (i, (i + 5) % n)))
            .chain((0..n).map(|i| (i, (i * 7 + 3) % n)))
            .filter(|(i, j)| i != j)
            .collect();
        let mut a = BlockCsr::with_pattern(n as usize, pairs.iter().copied());
        for &(i, j) in &pairs {
            // Add an element Hessian Bᵀ B on the pair: PSD and coupled.
            let b = nalgebra::SMatrix::<f64, 3, 6>::from_fn(|_, _| rnd());
            let h = b.transpose() * b;
            for (p, vp) in [i, j].iter().enumerate() {
                for (q, vq) in [i, j].iter().enumerate() {
                    a.add(*vp, *vq, &h.fixed_view::<3, 3>(3 * p, 3 * q).into_owned());
                }
            }
        }
        for i in 0..n {
            a.add(i, i, &(Matrix3::identity() * 0.01));
        }
        let mut free = vec![true; n as usize];
        free[7] = false;
        let b: Vec<Vector3<f64>> = (0..n)
            .map(|i| {
                if i == 7 {
                    Vector3::zeros()
                } else {
                    Vector3::new(rnd(), rnd(), rnd())
                }
            })
            .collect();
        let mut pre = CholeskyPreconditioner::new(&a).expect("symbolic");
        assert!(pre.factorize(&a, &free));
        let mut x = vec![Vector3::zeros(); n as usize];
        let stats = Pcg::default().solve_with_factor(&a, &b, &mut x, &free, &mut pre, 1e-10, 100);
        assert!(stats.iterations <= 1, "{stats:?}");
        let mut check = vec![Vector3::zeros(); n as usize];
        a.matvec(&x, &mut check, &free);
        let err = check
            .iter()
            .zip(&b)
            .map(|(p, q)| (p - q).norm())
            .fold(0.0, f64::max);
        assert!(err < 1e-8, "residual {err}");
    }
}

/// The coarse level of a two-level preconditioner (unsmoothed aggregation, as in algebraic
/// multigrid): vertices are grouped into aggregates of `size` consecutive vertices (meshes are
/// numbered along a Morton curve of material space, so these are compact patches), each
/// aggregate moves as one rigid translation, and the Galerkin matrix A_c = PᵀAP, P the 0/1
/// aggregate map, is factored sparsely. Added to block-Jacobi (M⁻¹ = D⁻¹ + P A_c⁻¹ Pᵀ, SPD),
/// it removes the smooth, cloth-wide error modes that Jacobi-preconditioned CG needs most of
/// its iterations for.
#[derive(Debug, Clone)]
pub struct TwoLevel {
    /// Aggregate of each vertex.
    aggregate: Vec<u32>,
    /// Coarse slot of every fine pattern block.
    slot: Vec<usize>,
    coarse: BlockCsr,
    factor: CholeskyPreconditioner,
    coarse_free: Vec<bool>,
    rc: Vec<Vector3<f64>>,
    zc: Vec<Vector3<f64>>,
}

impl TwoLevel {
    /// The coarse level for `a`'s pattern with aggregates of `size` vertices; `None` when the
    /// coarse matrix cannot be analysed.
    pub fn new(a: &BlockCsr, size: usize) -> Option<TwoLevel> {
        let n = a.n();
        let size = size.max(1);
        let aggregate: Vec<u32> = (0..n).map(|i| (i / size) as u32).collect();
        let nc = n.div_ceil(size);
        let rows = (0..n).flat_map(|i| std::iter::repeat_n(i, a.row_ptr[i + 1] - a.row_ptr[i]));
        let pairs: Vec<(u32, u32)> = rows
            .zip(&a.col)
            .map(|(i, &j)| (aggregate[i], aggregate[j as usize]))
            .filter(|(p, q)| p < q)
            .collect();
        let coarse = BlockCsr::with_pattern(nc, pairs);
        let slot = (0..n)
            .flat_map(|i| (a.row_ptr[i]..a.row_ptr[i + 1]).map(move |k| (i, k)))
            .map(|(i, k)| {
                coarse
                    .find(aggregate[i], aggregate[a.col[k] as usize])
                    .unwrap_or(usize::MAX)
            })
            .collect();
        let factor = CholeskyPreconditioner::new(&coarse)?;
        // faer's triangular solves are called once per CG iteration on a few thousand
        // unknowns, whose supernodes are too small to share between threads, so they run
        // sequentially. faer serves only the
        // simulator's preconditioners in this program.
        faer::set_global_parallelism(faer::Par::Seq);
        Some(TwoLevel {
            aggregate,
            slot,
            coarse,
            factor,
            coarse_free: vec![true; nc],
            rc: vec![Vector3::zeros(); nc],
            zc: vec![Vector3::zeros(); nc],
        })
    }

    /// Number of aggregates.
    pub fn num_aggregates(&self) -> usize {
        self.coarse.n()
    }

    /// Forms A_c = PᵀAP over the free vertices of `a` (extra blocks whose aggregates are not
    /// coupled in the pattern are left out: dropping the off-diagonal part of a PSD contact
    /// pair keeps A_c positive definite) and factors it. Returns false when the factorisation
    /// fails; the correction is then skipped until the next success.
    pub fn factorize(&mut self, a: &BlockCsr, free: &[bool]) -> bool {
        self.coarse.clear();
        let mut row = 0;
        for (k, (blk, &c)) in a.blocks.iter().zip(&self.slot).enumerate() {
            while k >= a.row_ptr[row + 1] {
                row += 1;
            }
            if c != usize::MAX && free[row] && free[a.col[k] as usize] {
                self.coarse.blocks[c] += blk;
            }
        }
        for (i, j, m) in &a.extra {
            let (i, j) = (*i as usize, *j as usize);
            if free[i] && free[j] {
                if let Some(c) = self.coarse.find(self.aggregate[i], self.aggregate[j]) {
                    self.coarse.blocks[c] += m;
                }
            }
        }
        // An aggregate of fixed vertices only has a zero row: hold it fixed.
        for (c, f) in self.coarse_free.iter_mut().enumerate() {
            *f = self.coarse.blocks[self.coarse.diag[c]] != Matrix3::zeros();
        }
        self.factor.factorize(&self.coarse, &self.coarse_free)
    }

    /// z += P A_c⁻¹ Pᵀ r (free vertices only).
    pub fn add_correction(&mut self, r: &[Vector3<f64>], z: &mut [Vector3<f64>], free: &[bool]) {
        if !self.factor.is_factored() {
            return;
        }
        self.rc.iter_mut().for_each(|v| *v = Vector3::zeros());
        for ((ri, &g), f) in r.iter().zip(&self.aggregate).zip(free) {
            if *f {
                self.rc[g as usize] += ri;
            }
        }
        self.factor.apply(&self.rc, &mut self.zc, &self.coarse_free);
        for ((zi, &g), f) in z.iter_mut().zip(&self.aggregate).zip(free) {
            if *f {
                *zi += self.zc[g as usize];
            }
        }
    }
}
