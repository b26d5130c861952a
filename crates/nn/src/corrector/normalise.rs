//! Zero-mean, unit-variance normalisation of the corrector's inputs and targets with data-set
//! statistics (the paper's §3.3.2), saved with the model as `normalisation.json`. Flag
//! features are left as they are.

use serde::{Deserialize, Serialize};

use super::graph::{EDGE_FEATURES, EDGE_FLAGS, NODE_FEATURES, NODE_FLAGS};

/// Smallest standard deviation used, so constant features do not blow up.
const MIN_STD: f64 = 1e-8;

/// Per-feature mean and standard deviation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Moments {
    /// Mean per feature.
    pub mean: Vec<f32>,
    /// Standard deviation per feature.
    pub std: Vec<f32>,
}

impl Moments {
    /// Normalises row-major rows of `mean.len()` features in place.
    pub fn apply(&self, rows: &mut [f32]) {
        for row in rows.chunks_exact_mut(self.mean.len()) {
            for ((x, m), s) in row.iter_mut().zip(&self.mean).zip(&self.std) {
                *x = (*x - m) / s;
            }
        }
    }

    /// Undoes [`Moments::apply`].
    pub fn invert(&self, rows: &mut [f32]) {
        for row in rows.chunks_exact_mut(self.mean.len()) {
            for ((x, m), s) in row.iter_mut().zip(&self.mean).zip(&self.std) {
                *x = *x * s + m;
            }
        }
    }
}

/// Accumulates [`Moments`] over rows.
#[derive(Debug, Clone)]
pub struct MomentsBuilder {
    count: f64,
    sum: Vec<f64>,
    sum_sq: Vec<f64>,
    flags: Vec<usize>,
    centred: bool,
}

impl MomentsBuilder {
    /// For rows of `width` features, of which `flags` are left unnormalised.
    pub fn new(width: usize, flags: &[usize]) -> MomentsBuilder {
        MomentsBuilder {
            count: 0.0,
            sum: vec![0.0; width],
            sum_sq: vec![0.0; width],
            flags: flags.to_vec(),
            centred: true,
        }
    }

    /// Scale only: the mean stays 0 and the scale is the root mean square, so that zero maps
    /// to zero.
    pub fn uncentred(mut self) -> MomentsBuilder {
        self.centred = false;
        self
    }

    /// Adds row-major rows.
    pub fn add(&mut self, rows: &[f32]) {
        for row in rows.chunks_exact(self.sum.len()) {
            self.count += 1.0;
            for (k, &x) in row.iter().enumerate() {
                self.sum[k] += f64::from(x);
                self.sum_sq[k] += f64::from(x) * f64::from(x);
            }
        }
    }

    /// The moments seen so far (identity for flags and when nothing was added).
    pub fn build(&self) -> Moments {
        let n = self.count.max(1.0);
        let (mut mean, mut std) = (Vec::new(), Vec::new());
        for k in 0..self.sum.len() {
            if self.flags.contains(&k) || self.count == 0.0 {
                mean.push(0.0);
                std.push(1.0);
                continue;
            }
            let m = if self.centred { self.sum[k] / n } else { 0.0 };
            let var = (self.sum_sq[k] / n - m * m).max(0.0);
            mean.push(m as f32);
            std.push(var.sqrt().max(MIN_STD) as f32);
        }
        Moments { mean, std }
    }
}

/// The statistics a corrector was trained with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Normalisation {
    /// Node features.
    pub nodes: Moments,
    /// Edge features.
    pub edges: Moments,
    /// Targets: velocity corrections p̄, m/s. Scaled but not shifted (mean 0): a network
    /// output of zero is then no correction, rather than the data set's mean correction
    /// applied everywhere. Interleaving feeds every correction back into the simulation, so
    /// a constant bias on states unlike the training data (free fall, say) would accumulate
    /// into drift.
    pub targets: Moments,
}

/// Accumulates a [`Normalisation`].
#[derive(Debug, Clone)]
pub struct NormalisationBuilder {
    nodes: MomentsBuilder,
    edges: MomentsBuilder,
    targets: MomentsBuilder,
}

impl Default for NormalisationBuilder {
    fn default() -> Self {
        NormalisationBuilder {
            nodes: MomentsBuilder::new(NODE_FEATURES, &NODE_FLAGS),
            edges: MomentsBuilder::new(EDGE_FEATURES, &EDGE_FLAGS),
            targets: MomentsBuilder::new(3, &[]).uncentred(),
        }
    }
}

impl NormalisationBuilder {
    /// Adds one sample's raw features and targets.
    pub fn add(&mut self, nodes: &[f32], edges: &[f32], targets: &[f32]) {
        self.nodes.add(nodes);
        self.edges.add(edges);
        self.targets.add(targets);
    }

    /// The statistics.
    pub fn build(&self) -> Normalisation {
        Normalisation {
            nodes: self.nodes.build(),
            edges: self.edges.build(),
            targets: self.targets.build(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalised_features_have_zero_mean_unit_variance_and_flags_stay() {
        let mut b = MomentsBuilder::new(3, &[2]);
        let rows: Vec<f32> = (0..100)
            .flat_map(|i| [i as f32 * 0.1, 5.0 - i as f32, (i % 2) as f32])
            .collect();
        b.add(&rows);
        let m = b.build();
        let mut x = rows.clone();
        m.apply(&mut x);
        for k in 0..2 {
            let col: Vec<f64> = x.chunks(3).map(|r| f64::from(r[k])).collect();
            let mean = col.iter().sum::<f64>() / 100.0;
            let var = col.iter().map(|c| (c - mean).powi(2)).sum::<f64>() / 100.0;
            assert!(
                mean.abs() < 1e-5 && (var - 1.0).abs() < 1e-4,
                "{k}: {mean} {var}"
            );
        }
        assert!(x.chunks(3).zip(rows.chunks(3)).all(|(a, b)| a[2] == b[2]));
        m.invert(&mut x);
        assert!(x.iter().zip(&rows).all(|(a, b)| (a - b).abs() < 1e-4));

        // Uncentred: mean 0, scale = RMS (of 3 and 4: 3.5355).
        let mut u = MomentsBuilder::new(1, &[]).uncentred();
        u.add(&[3.0, -4.0]);
        let m = u.build();
        assert_eq!(m.mean, vec![0.0]);
        assert!((m.std[0] - 12.5f32.sqrt()).abs() < 1e-5, "{:?}", m.std);
    }
}
