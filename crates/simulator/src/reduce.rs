//! Parallel sums whose bits do not depend on the number of threads.
//!
//! Floating-point addition is not associative, and rayon's `sum` adds partial sums in the order
//! its work stealing happened to split the range: the same step on one thread and on two gives
//! energies that differ in the last bits, and the line search, whose Armijo test compares such
//! sums, can then take another branch. Trajectories that are sensitive to rounding (a garment's
//! stalled seams, a drape at rest on a ball) then depend on the machine. Here every sum is split
//! into fixed chunks of [`CHUNK`] consecutive items, each chunk is added in order on one
//! thread, and the chunk sums are added in order: one result, on any number of threads, so
//! small meshes can use every core and still come out the same everywhere.

use rayon::prelude::*;

/// Items per chunk of a sum.
pub const CHUNK: usize = 512;

/// Σ `f(i)` for `i` in `0..n`, in parallel, the same on any number of threads.
pub fn sum(n: usize, f: impl Fn(usize) -> f64 + Sync) -> f64 {
    sum_split(n, 1, f)
}

/// As [`sum`], a thread taking at least `min_chunks` chunks at a time (`usize::MAX`: all on
/// the calling thread, with the same result).
pub fn sum_split(n: usize, min_chunks: usize, f: impl Fn(usize) -> f64 + Sync) -> f64 {
    in_order(
        (0..n.div_ceil(CHUNK))
            .into_par_iter()
            .with_min_len(min_chunks.max(1))
            .map(|c| (c * CHUNK..((c + 1) * CHUNK).min(n)).map(&f).sum::<f64>())
            .collect(),
    )
}

/// Σ `a[i]·b[i]`, the same on any number of threads; `min_len` as in [`sum_split`].
pub fn dot(a: &[nalgebra::Vector3<f64>], b: &[nalgebra::Vector3<f64>], min_len: usize) -> f64 {
    assert_eq!(a.len(), b.len(), "dot of vectors of different lengths");
    // Slices, not indices: an indexed closure here made CG's dots much slower.
    let chunk_dot = |(x, y): (&[nalgebra::Vector3<f64>], &[nalgebra::Vector3<f64>])| {
        x.iter().zip(y).map(|(p, q)| p.dot(q)).sum::<f64>()
    };
    if min_len == usize::MAX {
        // The same chunks in the same order on the calling thread, without rayon's bridge
        // (nor a vector of chunk sums).
        return a
            .chunks(CHUNK)
            .zip(b.chunks(CHUNK))
            .map(chunk_dot)
            .fold(0.0, |acc, s| acc + s);
    }
    in_order(
        a.par_chunks(CHUNK)
            .zip(b.par_chunks(CHUNK))
            .with_min_len(min_len.max(1))
            .map(chunk_dot)
            .collect(),
    )
}

/// The chunk sums `parts` added in order.
pub fn in_order(parts: Vec<f64>) -> f64 {
    parts.into_iter().fold(0.0, |acc, s| acc + s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values spread over many magnitudes, so that the order of addition shows in the bits.
    fn values(n: usize) -> Vec<f64> {
        let mut s = 0x9e37_79b9_7f4a_7c15_u64;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                let u = (s >> 11) as f64 / (1u64 << 53) as f64;
                (u - 0.5) * 10f64.powi((s % 17) as i32 - 8)
            })
            .collect()
    }

    #[test]
    fn sums_are_the_same_bits_on_any_number_of_threads() {
        for n in [0, 1, CHUNK - 1, CHUNK, CHUNK + 1, 10 * CHUNK + 7, 40_000] {
            let v = values(n);
            let run = |threads: usize| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .expect("pool")
                    .install(|| sum(n, |i| v[i]))
                    .to_bits()
            };
            let one = run(1);
            for threads in [2, 3, 8] {
                assert_eq!(one, run(threads), "n = {n}, {threads} threads");
            }
            let one = f64::from_bits(one);
            assert_eq!(one.to_bits(), sum_split(n, usize::MAX, |i| v[i]).to_bits());
            // And it is the sum, to rounding.
            let plain: f64 = v.iter().sum();
            let scale: f64 = v.iter().map(|x| x.abs()).sum();
            assert!(
                (one - plain).abs() <= 1e-12 * scale.max(1e-300),
                "{one} vs {plain}"
            );
        }
    }
}
