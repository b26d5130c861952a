//! Conflict-free parallel assembly. Elements are split into colours so that no two elements of
//! one colour share a vertex; the elements of a colour then add their gradient and Hessian blocks
//! straight into the global arrays in parallel (every block (i, j) and gradient entry i they
//! touch belongs to their own vertices only), and colours run one after another. This fuses the
//! element computation with the scatter: no per-element 9×9 / 12×12 buffers travel through
//! memory (at 40K vertices those were ~200 MB per Newton iteration), and the summation order of
//! every entry is fixed by the colouring, so results do not depend on the thread count.
//!
//! `unsafe` is allowed here for a private slice writer (elsewhere only for the one call into
//! `gemm`'s matrix kernels in `corrector::fused`, whose API takes raw pointers): Rust cannot
//! see that the colouring makes the parallel writes disjoint, so the writer hands out `&mut`
//! to entries of a slice from several threads. [`ColouredElements`] keeps the colouring and the block slots
//! together (built from the matrix, private fields), which is what makes that sound; every
//! access is bounds-checked.
#![allow(unsafe_code)]

use std::marker::PhantomData;

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use rayon::prelude::*;

use super::sparse::BlockCsr;

/// Elements per chunk: chunks of consecutive elements are coloured and run as units, which
/// keeps each thread's writes within one region of the mesh (cache locality), where colouring
/// single elements would sweep the whole matrix once per colour.
pub const CHUNK: usize = 128;

/// Groups of chunk indices (chunk c = elements `c·chunk ..`) such that no two chunks of a
/// group share a vertex (greedy colouring in chunk order).
pub fn colour_chunks<const N: usize>(
    elements: &[[u32; N]],
    n_vertices: usize,
    chunk: usize,
) -> Vec<Vec<u32>> {
    // Colours used so far at each vertex, in 64-colour words.
    let mut used: Vec<Vec<u64>> = vec![Vec::new(); n_vertices];
    let mut colours: Vec<Vec<u32>> = Vec::new();
    let mut verts: Vec<u32> = Vec::new();
    for (k, chunk) in elements.chunks(chunk.max(1)).enumerate() {
        verts.clear();
        verts.extend(chunk.iter().flatten());
        verts.sort_unstable();
        verts.dedup();
        let words = verts
            .iter()
            .map(|&v| used[v as usize].len())
            .max()
            .unwrap_or(0);
        let mut c = 64 * words;
        for w in 0..=words {
            let taken = verts
                .iter()
                .map(|&v| used[v as usize].get(w).copied().unwrap_or(0))
                .fold(0u64, |a, b| a | b);
            if taken != u64::MAX {
                c = 64 * w + (!taken).trailing_zeros() as usize;
                break;
            }
        }
        for &v in &verts {
            let u = &mut used[v as usize];
            if u.len() <= c / 64 {
                u.resize(c / 64 + 1, 0);
            }
            u[c / 64] |= 1 << (c % 64);
        }
        if colours.len() <= c {
            colours.resize_with(c + 1, Vec::new);
        }
        colours[c].push(k as u32);
    }
    colours
}

/// Elements of N vertices, coloured, with the matrix slots of their N×N blocks: the safe face
/// of the parallel scatter. Built against one [`BlockCsr`] and used with it only.
#[derive(Debug, Clone, Default)]
pub struct ColouredElements<const N: usize, const NN: usize> {
    vertices: Vec<[u32; N]>,
    slots: Vec<[usize; NN]>,
    colours: Vec<Vec<u32>>,
    n_vertices: usize,
    n_blocks: usize,
}

impl<const N: usize, const NN: usize> ColouredElements<N, NN> {
    /// Colours `vertices` and finds their blocks in `matrix`, whose pattern must hold every
    /// pair of vertices of an element (panics otherwise: a construction bug).
    pub fn new(vertices: Vec<[u32; N]>, matrix: &BlockCsr) -> Self {
        assert_eq!(N * N, NN, "NN must be N²");
        let slots = vertices
            .iter()
            .map(|v| {
                std::array::from_fn(|k| {
                    let (a, b) = (v[k / N], v[k % N]);
                    matrix
                        .find(a, b)
                        .unwrap_or_else(|| panic!("block ({a}, {b}) is not in the pattern"))
                })
            })
            .collect();
        let colours = colour_chunks(&vertices, matrix.n(), CHUNK);
        ColouredElements {
            vertices,
            slots,
            colours,
            n_vertices: matrix.n(),
            n_blocks: matrix.nnz_blocks(),
        }
    }

    /// Number of colours.
    pub fn num_colours(&self) -> usize {
        self.colours.len()
    }

    /// Adds every element's gradient (3N) and Hessian (3N×3N) from `element(k)` into `grad`
    /// and `matrix`, colour after colour, elements of a colour in parallel; returns the sum of
    /// their energies.
    pub fn add<const M: usize>(
        &self,
        matrix: &mut BlockCsr,
        grad: &mut [Vector3<f64>],
        element: impl Fn(usize) -> (f64, SVector<f64, M>, SMatrix<f64, M, M>) + Sync,
    ) -> f64 {
        assert_eq!(M, 3 * N, "M must be 3N");
        assert_eq!(grad.len(), self.n_vertices, "gradient of another mesh");
        assert_eq!(matrix.n(), self.n_vertices, "matrix of another mesh");
        assert_eq!(
            matrix.nnz_blocks(),
            self.n_blocks,
            "matrix of another pattern"
        );
        let blocks = DisjointWriter::new(&mut matrix.blocks);
        let grad = DisjointWriter::new(grad);
        let mut energy = 0.0;
        for colour in &self.colours {
            let sums: Vec<f64> = colour
                .par_iter()
                .map(|&c| {
                    let first = c as usize * CHUNK;
                    let last = (first + CHUNK).min(self.vertices.len());
                    let mut sum = 0.0;
                    for k in first..last {
                        let (e, g, hm) = element(k);
                        let (v, slots) = (&self.vertices[k], &self.slots[k]);
                        for a in 0..N {
                            // SAFETY: the chunks of a colour share no vertex, so entry v[a] of
                            // the gradient and the blocks of row v[a] (all of this element's
                            // slots lie in its own rows) are written by this chunk's thread
                            // alone, one element after another.
                            unsafe {
                                *grad.get(v[a] as usize) += g.fixed_rows::<3>(3 * a);
                                for b in 0..N {
                                    *blocks.get(slots[N * a + b]) +=
                                        hm.fixed_view::<3, 3>(3 * a, 3 * b);
                                }
                            }
                        }
                        sum += e;
                    }
                    sum
                })
                .collect();
            energy += super::reduce::in_order(sums);
        }
        energy
    }
}

/// Runs `f(i)` for every vertex in parallel with exclusive access to gradient entry i and
/// diagonal block i of `matrix`; returns the sum of what it returns.
pub fn for_each_vertex(
    matrix: &mut BlockCsr,
    grad: &mut [Vector3<f64>],
    f: impl Fn(usize, &mut Vector3<f64>, &mut Matrix3<f64>) -> f64 + Sync,
) -> f64 {
    let (blocks, diag) = matrix.blocks_and_diag_mut();
    assert_eq!(grad.len(), diag.len(), "gradient of another mesh");
    let blocks = DisjointWriter::new(blocks);
    // Fixed chunks added in order: the same bits on any number of threads (see reduce).
    let parts = grad
        .par_chunks_mut(super::reduce::CHUNK)
        .enumerate()
        .map(|(c, gs)| {
            let mut sum = 0.0;
            for (k, g) in gs.iter_mut().enumerate() {
                let i = c * super::reduce::CHUNK + k;
                // SAFETY: diagonal slots of distinct rows are distinct.
                let d = unsafe { blocks.get(diag[i]) };
                sum += f(i, g, d);
            }
            sum
        })
        .collect();
    super::reduce::in_order(parts)
}

/// Shared mutable access to a slice for writers that never touch the same entry at the same
/// time (the elements of one colour).
struct DisjointWriter<'a, T> {
    ptr: *mut T,
    len: usize,
    _slice: PhantomData<&'a mut [T]>,
}

// SAFETY: the writer is only a pointer to a slice it borrows mutably for 'a; sharing it across
// threads is sound as long as no two threads access the same entry concurrently, which is the
// contract of `get`.
unsafe impl<T: Send> Send for DisjointWriter<'_, T> {}
unsafe impl<T: Send> Sync for DisjointWriter<'_, T> {}

impl<'a, T> DisjointWriter<'a, T> {
    fn new(slice: &'a mut [T]) -> DisjointWriter<'a, T> {
        DisjointWriter {
            ptr: slice.as_mut_ptr(),
            len: slice.len(),
            _slice: PhantomData,
        }
    }

    /// Entry `i` (panics when out of bounds).
    ///
    /// # Safety
    /// No other reference to entry `i` may be alive while the returned one is.
    #[allow(clippy::mut_from_ref)]
    unsafe fn get(&self, i: usize) -> &mut T {
        assert!(i < self.len, "index {i} out of bounds ({})", self.len);
        // SAFETY: in bounds (checked above); exclusivity is the caller's contract.
        unsafe { &mut *self.ptr.add(i) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check<const N: usize>(elements: &[[u32; N]], n: usize, chunk: usize) -> usize {
        let colours = colour_chunks(elements, n, chunk);
        let mut seen = vec![false; elements.len()];
        for colour in &colours {
            // Vertex → chunk that used it in this colour.
            let mut owner = vec![u32::MAX; n];
            for &c in colour {
                let first = c as usize * chunk;
                for k in first..(first + chunk).min(elements.len()) {
                    assert!(!seen[k], "element {k} in two colours");
                    seen[k] = true;
                    for &v in &elements[k] {
                        let o = &mut owner[v as usize];
                        assert!(
                            *o == u32::MAX || *o == c,
                            "vertex {v} in two chunks of a colour"
                        );
                        *o = c;
                    }
                }
            }
        }
        assert!(seen.iter().all(|&s| s), "an element has no colour");
        colours.len()
    }

    #[test]
    fn colours_of_a_grid_mesh_share_no_vertex_and_are_few() {
        let w = 30u32;
        let mut tris = Vec::new();
        for j in 0..w - 1 {
            for i in 0..w - 1 {
                let a = j * w + i;
                tris.push([a, a + 1, a + w + 1]);
                tris.push([a, a + w + 1, a + w]);
            }
        }
        let c = check(&tris, (w * w) as usize, 1);
        // Six triangles meet at an interior vertex of this grid: greedy needs few more.
        assert!((6..=12).contains(&c), "{c} colours");
        // Chunks of consecutive rows: each conflicts only with the rows beside it.
        let c = check(&tris, (w * w) as usize, 2 * (w as usize - 1));
        assert!((2..=3).contains(&c), "{c} colours of row chunks");
    }

    #[test]
    fn more_than_64_colours_spill_into_a_second_word() {
        // 100 edges all sharing vertex 0: every one needs its own colour.
        let star: Vec<[u32; 2]> = (1..=100).map(|i| [0, i]).collect();
        assert_eq!(check(&star, 101, 1), 100);
        assert_eq!(check(&star, 101, 7), 15);
    }
}
