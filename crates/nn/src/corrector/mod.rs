//! The corrector (the paper's §3.1.2–3.1.3, §3.3.2): a MeshGraphNets-style graph network that
//! turns the coarse simulator's step M_c into M_int, the coarse mesh whose low-frequency shape
//! matches the downsampled fine simulation, by a velocity correction p: q′ = q + p,
//! x′ = x + h·p. The simulator then advances from M_int (interleaving).
//!
//! * [`graph`]: the coarse mesh as a graph, node and edge features;
//! * [`normalise`]: data-set statistics;
//! * [`model`]: the burn network (encode–process–decode, optional attention);
//! * [`fused`]: the same network's forward pass on the CPU outside burn, for inference;
//! * [`data`]: samples from data sets made by [`clothsr_io::data`];
//! * [`training`]: one-step training with noise and patches, then window rollout training;
//! * [`inference`]: the [`Corrector`] the simulation loop calls after every step;
//! * [`rollout`]: rollout errors against the ground truth, with the paper's ablations.

/// `with_<field>` setters for a configuration's fields, each returning the configuration with
/// one field changed: `setters!(Type { with_x: x: T, … })`.
macro_rules! setters {
    ($ty:ty { $($with:ident: $field:ident: $t:ty),* $(,)? }) => {
        impl $ty {
            $(
                #[doc = concat!("The same with `", stringify!($field), "` set to `value`.")]
                #[must_use]
                pub fn $with(mut self, value: $t) -> Self {
                    self.$field = value;
                    self
                }
            )*
        }
    };
}

pub mod data;
pub mod fused;
pub mod graph;
pub mod inference;
pub mod model;
pub mod normalise;
pub mod rollout;
pub mod training;

pub use inference::Corrector;
pub use model::{CorrectorConfig, CorrectorNet};
pub use training::{train, TrainingConfig};
