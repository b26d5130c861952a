//! Command-line interface: one module per command; each turns its arguments into library calls.

mod convert;
mod eval;
mod fit;
mod inspect;
mod lab;
mod mesh;
mod run;
mod simulate;
mod values;

use std::path::{Path, PathBuf};

use anyhow::bail;
use clap::{Parser, Subcommand};
use clothsr::garment::FabricPreset;
use clothsr::io::SceneFiles;
use clothsr::pipeline::shot::RunSummary;
use clothsr::pipeline::CoarseCalibration;
use clothsr::ErrorKind;

/// Super-resolution cloth animation: coarse simulation, learned correction, fine wrinkles.
#[derive(Debug, Parser)]
#[command(
    name = "clothsr",
    version,
    about,
    after_help = "Exit status: 0 done; 2 bad usage (the command line); 3 bad input (a file's \
                  content, named with the element at fault); 4 failure while running (a \
                  simulation that cannot go on, a full disk). A batch goes on past a failing \
                  shot and exits with the most severe of its failures."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Log more (-v: debug, -vv: trace); RUST_LOG overrides.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    /// Print a JSON summary on stdout at the end: status, exit code, each shot of a run with
    /// its frames or its error (kind `usage`, `input` or `failure`, and message).
    #[arg(long, global = true)]
    json: bool,
    /// The units of USD files that do not state them (no `metersPerUnit`), in metres per
    /// unit: 0.01 for centimetres. Without it such files are refused.
    #[arg(long, global = true, value_name = "M", value_parser = values::positive(1e3))]
    meters_per_unit: Option<f64>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The whole pipeline on a scene: coarse simulation, corrector, mesh super-resolution,
    /// fine garments to time-sampled USD.
    Run(run::Args),
    /// The best models for one garment and shot: simulations of variations of it, the coarse
    /// model calibrated, the ISR network fine-tuned, a held-out report.
    Fit(fit::Args),
    /// Errors of a run's fine meshes (and baselines) against a fine simulation: table, CSV,
    /// plot over time, Rerun heat map.
    Eval(eval::Args),
    /// What is in a pattern, mesh, scene or avatar file.
    Inspect(inspect::Args),
    /// GarmentCode JSON or OBJ (+ colliders, avatar) to a USD scene using clothsr's schema.
    Convert(convert::Args),
    /// Mesh a garment at a target edge length and write it with material coordinates.
    Mesh(mesh::Args),
    /// Simulate a scene's cloth and write the animation to USD.
    Simulate(simulate::Args),
    /// Research tools: training data, training, rollouts, calibration, benchmarks.
    #[command(subcommand)]
    Lab(Box<lab::Command>),
}

/// Runs the command line and returns the exit code, printing errors with their causes (and
/// the `--json` summary).
pub fn run() -> i32 {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return refused(&e),
    };
    let default = match cli.verbose {
        0 => "info",
        1 => "debug",
        _ => "trace",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .init();
    let outcome = assume_units(cli.meters_per_unit).and_then(|()| match cli.command {
        Command::Run(a) => run::run(a),
        Command::Fit(a) => fit::run(a).map(|()| none_run()),
        Command::Eval(a) => eval::run(a).map(|()| none_run()),
        Command::Inspect(a) => inspect::run(a).map(|()| none_run()),
        Command::Convert(a) => convert::run(a).map(|()| none_run()),
        Command::Mesh(a) => mesh::run(a).map(|()| none_run()),
        Command::Simulate(a) => simulate::run(a).map(|()| none_run()),
        Command::Lab(c) => lab::run(*c),
    });
    let summary = match outcome {
        Ok(summary) => summary,
        Err(err) => {
            eprintln!("error: {err:#}");
            RunSummary::of(Vec::new(), Some((error_kind(&err), format!("{err:#}"))))
        }
    };
    if cli.json {
        match serde_json::to_string(&summary) {
            Ok(text) => println!("{text}"),
            Err(e) => eprintln!("error: cannot write the JSON summary: {e}"),
        }
    }
    summary.exit_code
}

/// Prints clap's refusal of the command line (or the help or version asked for) and returns
/// its exit code; with `--json`, a refusal's summary too.
fn refused(e: &clap::Error) -> i32 {
    let _ = e.print();
    let code = e.exit_code();
    if e.use_stderr() && std::env::args_os().any(|a| a == "--json") {
        let summary = RunSummary::of(Vec::new(), Some((ErrorKind::Usage, e.kind().to_string())));
        if let Ok(text) = serde_json::to_string(&summary) {
            println!("{text}");
        }
        return summary.exit_code;
    }
    code
}

/// Takes `--meters-per-unit` for USD files that state no units.
fn assume_units(meters_per_unit: Option<f64>) -> anyhow::Result<()> {
    if let Some(m) = meters_per_unit {
        clothsr::io::usd::assume_meters_per_unit(Some(m))?;
        tracing::info!("USD files without metersPerUnit are read in {m} m per unit");
    }
    Ok(())
}

/// The summary of a command that runs no shots and succeeded.
fn none_run() -> RunSummary {
    RunSummary::of(Vec::new(), None)
}

/// What kind of failure `err` is: the library's kind where it comes from the library, an I/O
/// failure as such, else the command line's own checks (bad usage).
pub(crate) fn error_kind(err: &anyhow::Error) -> ErrorKind {
    for cause in err.chain() {
        if let Some(e) = cause.downcast_ref::<clothsr::Error>() {
            return e.kind();
        }
        if cause.downcast_ref::<std::io::Error>().is_some() {
            return ErrorKind::Failure;
        }
    }
    ErrorKind::Usage
}

/// The coarse mesh's edge length, mm: the default of every `--edge-mm`/`--coarse-mm`.
pub(crate) const COARSE_MM: f64 = clothsr::mesh::COARSE_EDGE_M * 1e3;

/// The coarse model's settings on the command line (`--coarse-*`); each unset is the
/// simulator's own. See [`CoarseCalibration`].
#[derive(Debug, Clone, Copy, Default, clap::Args)]
pub(crate) struct CoarseArgs {
    /// The coarse membrane's stiffness under compression, as a factor in (0, 1] of its stretch
    /// stiffness: below 1 the coarse mesh gives way to the shortening the fine cloth takes up
    /// in wrinkles.
    #[arg(value_parser = values::positive(1.0), long = "coarse-compression", value_name = "FACTOR")]
    compression: Option<f64>,
    /// The shortening (1 − stretch ratio, > 0) beyond which the compression-soft coarse
    /// membrane is stiff again, as the fine cloth's wrinkles pack tight (0: none).
    #[arg(value_parser = values::non_negative(1.0), long = "coarse-compression-knee", value_name = "SHORTENING")]
    compression_knee: Option<f64>,
    /// The coarse simulation's Coulomb friction coefficient against bodies, ≥ 0.
    #[arg(value_parser = values::non_negative(100.0), long = "coarse-friction", value_name = "MU")]
    friction: Option<f64>,
    /// The wrinkle bending gain: extra bending stiffness where the coarse membrane is
    /// shortened, up to this multiple of the fabric's, fading in as the cloth's mean speed
    /// falls from 6 cm/s to rest (0: off).
    #[arg(value_parser = values::non_negative(values::MAX_FACTOR), long = "coarse-wrinkle-bending", value_name = "GAIN")]
    wrinkle_bending: Option<f64>,
    /// The coarse hinges' bending stiffness as a factor of the fabric's, > 0 (1: the
    /// fabric's).
    #[arg(value_parser = values::positive(values::MAX_FACTOR), long = "coarse-bending", value_name = "FACTOR")]
    bending: Option<f64>,
    /// Whether coarse cloth edges meet the colliders' sharp edges, `on` or `off`; off, a 20 mm
    /// edge may cut a table's corner as the downsampled fine cloth's do.
    #[arg(long = "coarse-crease-contacts", value_name = "on|off", value_parser = values::on_off())]
    crease_contacts: Option<bool>,
}

impl CoarseArgs {
    /// The settings given.
    pub(crate) fn calibration(&self) -> CoarseCalibration {
        CoarseCalibration {
            compression: self.compression,
            compression_knee: self.compression_knee,
            friction: self.friction,
            wrinkle_bending: self.wrinkle_bending,
            bending: self.bending,
            crease_contacts: self.crease_contacts,
        }
    }
}

/// Checks the output before any work: a USD extension, and not the input file itself.
pub(crate) fn check_output(input: &Path, output: &Path) -> anyhow::Result<PathBuf> {
    clothsr::io::usd::check_extension(output)?;
    if let (Ok(a), Ok(b)) = (input.canonicalize(), output.canonicalize()) {
        if a == b {
            bail!("{}: the output would overwrite the input", output.display());
        }
    }
    Ok(output.to_path_buf())
}

/// A scene's extra inputs, as `clothsr lab dataset` records them and `clothsr run` replays them.
#[derive(Debug, clap::Args)]
pub(crate) struct SceneInputs {
    /// Extra colliders (OBJ, OBJ sequence, USD).
    #[arg(value_parser = values::input_file, long)]
    pub(crate) collider: Vec<PathBuf>,
    /// Avatar (USD, UsdSkel or point cache).
    #[arg(value_parser = values::input_file, long)]
    pub(crate) avatar: Option<PathBuf>,
    /// Fabric preset for patterns and meshes without one.
    #[arg(long, default_value = "cotton")]
    pub(crate) fabric: FabricPreset,
}

impl SceneInputs {
    /// The shot `path` with these inputs.
    pub(crate) fn source(&self, path: &Path) -> clothsr::data::SceneSource {
        clothsr::data::SceneSource {
            scene: path.to_path_buf(),
            colliders: self.collider.clone(),
            avatar: self.avatar.clone(),
            fabric: self.fabric.name().to_string(),
        }
    }

    /// The scene file `path` with this fabric for what has none, these colliders and this
    /// avatar.
    pub(crate) fn load(&self, path: &Path) -> anyhow::Result<clothsr::scene::Scene> {
        let mut scene = clothsr::scene::Scene::load(path, &self.fabric.fabric())?;
        for c in self.collider.iter().chain(&self.avatar) {
            scene.add_collider_file(c)?;
        }
        Ok(scene)
    }
}

/// A variation of a scene, as `clothsr lab dataset` makes training sequences and `clothsr run`
/// replays them.
#[derive(Debug, Default, clap::Args)]
pub(crate) struct VariationArgs {
    /// Variation: move the garments by x,y,z metres (e.g. a drop height).
    #[arg(long, value_parser = values::triple, allow_hyphen_values = true)]
    garment_offset: Option<[f64; 3]>,
    /// Variation: move the colliders by x,y,z metres.
    #[arg(long, value_parser = values::triple, allow_hyphen_values = true)]
    collider_offset: Option<[f64; 3]>,
    /// Variation: turn the garments about the vertical axis, degrees.
    #[arg(value_parser = values::within(-3600.0, 3600.0), long, default_value_t = 0.0, allow_hyphen_values = true)]
    garment_yaw_deg: f64,
    /// Variation: start animated colliders (an avatar's clip) this many seconds in.
    #[arg(value_parser = values::non_negative(values::MAX_S), long, default_value_t = 0.0)]
    clip_start_s: f64,
}

impl VariationArgs {
    /// The variation.
    pub(crate) fn variation(&self) -> clothsr::data::Variation {
        clothsr::data::Variation {
            garment_offset_m: self.garment_offset.unwrap_or_default(),
            collider_offset_m: self.collider_offset.unwrap_or_default(),
            garment_yaw_deg: self.garment_yaw_deg,
            clip_start_s: self.clip_start_s,
        }
    }
}

#[cfg(test)]
mod hostile;
