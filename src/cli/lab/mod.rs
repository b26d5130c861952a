//! `clothsr lab …`: the research tools behind the shipped models — training data, training,
//! rollouts, calibration, benchmarks and the pipeline with every research setting. Users'
//! commands live one level up.

mod bench;
mod calibrate;
mod converge;
mod dataset;
mod fork;
mod rollout;
mod samples;
mod scenes;
mod sr;
mod train;

use clap::Subcommand;

/// The research commands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Training data: a fine simulation, its coarse downsampling (M_int) and one coarse step
    /// from each (M_c).
    Dataset(dataset::Args),
    /// Continue a data set from one of its frames with the fine garment moved a little: the
    /// ground truth's predictability floor (`eval --baseline floor=FORK`).
    Fork(fork::Args),
    /// Train a network (the corrector or the ISR network) on data sets.
    Train(train::Args),
    /// Roll the corrector out against a data set's ground truth, beside the coarse simulation
    /// alone and the corrector without interleaving.
    Rollout(rollout::Args),
    /// Choose the coarse model (membrane compression and its knee, friction, wrinkle bending,
    /// bending stiffness, crease contacts) that keeps the coarse simulation alone closest to a
    /// scene's M_int on its data sets, and write it as a models folder's coarse.json.
    Calibrate(calibrate::Args),
    /// Super-resolve a data set's M_int sequence with an ISR model and measure the fine meshes
    /// against the fine simulation, beside the upsampled coarse mesh.
    Sr(sr::Args),
    /// The whole pipeline with every research setting (coarse model, variations, extra
    /// outputs).
    Run(Box<super::run::LabArgs>),
    /// How far the fine simulation's solver modes and coarser resolutions are from a tight
    /// reference of the same shot, frame by frame, with their solver work and wall time.
    Converge(converge::Args),
    /// Benchmarks (the simulator side by side with Newton 1.8; the pipeline's stages).
    Bench(bench::Args),
    /// Regenerate the sample scenes shipped in samples/.
    Samples(samples::Args),
    /// Write the procedural shots the generic models are trained and measured on (USD).
    Scenes(scenes::Args),
}

/// Runs a research command.
pub fn run(command: Command) -> anyhow::Result<clothsr::pipeline::shot::RunSummary> {
    let done = clothsr::pipeline::shot::RunSummary::of(Vec::new(), None);
    match command {
        Command::Dataset(a) => dataset::run(a),
        Command::Fork(a) => fork::run(a),
        Command::Train(a) => train::run(a),
        Command::Rollout(a) => rollout::run(a),
        Command::Calibrate(a) => calibrate::run(a),
        Command::Sr(a) => sr::run(a),
        Command::Run(a) => return super::run::run_lab(*a),
        Command::Converge(a) => converge::run(a),
        Command::Bench(a) => bench::run(a),
        Command::Samples(a) => samples::run(a),
        Command::Scenes(a) => scenes::run(a),
    }
    .map(|()| done)
}
