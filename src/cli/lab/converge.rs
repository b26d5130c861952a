//! `clothsr lab converge SHOT… -o DIR`: the convergence harness ([`clothsr::eval::converge`]).

use std::path::PathBuf;

use clothsr::eval::converge::{converge, shot_dir, ModeSpec, Plan};
use clothsr::io::SceneFiles;
use clothsr::scene::{catalogue, Scene};

/// Arguments of `converge`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Shots: scene files (USD, GarmentCode JSON, OBJ) or procedural shot names
    /// (`garment-fabric-collider-motion`, as `lab scenes` writes them).
    #[arg(required = true)]
    shots: Vec<String>,
    /// Output directory: one folder per shot with its runs (a run already there is reused),
    /// `frames.csv`, and `converge.md` with every shot's table.
    #[arg(value_parser = crate::cli::values::output_dir, short, long)]
    output: PathBuf,
    /// Output frames.
    #[arg(long, default_value_t = 30)]
    frames: usize,
    /// Fine edge length, millimetres.
    #[arg(value_parser = crate::cli::values::positive(crate::cli::values::MAX_MM), long, default_value_t = 2.5)]
    fine_mm: f64,
    /// The reference's solver mode (`MODE/N`: the scene's time step divided by N).
    #[arg(long, default_value = "tight/4", value_parser = mode_spec)]
    reference: ModeSpec,
    /// The reference solved tighter still, to show it has converged ('none' to skip).
    #[arg(long, default_value = "tight/8", value_parser = check_spec)]
    check: std::option::Option<ModeSpec>,
    /// Solver modes measured at the fine resolution.
    #[arg(long, value_delimiter = ',', default_value = "fast,data", value_parser = mode_spec)]
    modes: Vec<ModeSpec>,
    /// The reference's twin, started this many millimetres higher (0: none).
    #[arg(value_parser = crate::cli::values::non_negative(crate::cli::values::MAX_MM), long, default_value_t = 0.1)]
    twin_mm: f64,
    /// Coarser resolutions measured against the fine reference, millimetres ('none' for none).
    #[arg(long, default_value = "20,10,5", value_parser = ladder)]
    ladder_mm: std::vec::Vec<f64>,
    /// The solver mode of the ladder's runs.
    #[arg(long, default_value = "data", value_parser = mode_spec)]
    ladder_mode: ModeSpec,
    /// Run the ladder's levels only with their own contact thickness (15 % of their edge), not
    /// also with the fine mesh's (as the pipeline's coarse simulation runs).
    #[arg(long)]
    ladder_own_thickness_only: bool,
    /// Cloth self-collision in every run, `on` or `off` (as `lab dataset --self-collision`).
    #[arg(long, default_value = "on", value_name = "on|off", value_parser = crate::cli::values::on_off(), action = clap::ArgAction::Set)]
    self_collision: bool,
    /// Coarse edge length for dressing garments with seams, millimetres.
    #[arg(value_parser = crate::cli::values::positive(crate::cli::values::MAX_MM), long, default_value_t = crate::cli::COARSE_MM)]
    coarse_mm: f64,
    #[command(flatten)]
    inputs: crate::cli::SceneInputs,
}

fn mode_spec(s: &str) -> Result<ModeSpec, String> {
    ModeSpec::parse(s).map_err(|e| e.to_string())
}

/// A mode, or `none`.
fn check_spec(s: &str) -> Result<Option<ModeSpec>, String> {
    match s {
        "none" => Ok(None),
        s => mode_spec(s).map(Some),
    }
}

/// Millimetres, comma-separated, or `none`.
fn ladder(s: &str) -> Result<Vec<f64>, String> {
    if s == "none" {
        return Ok(Vec::new());
    }
    s.split(',')
        .map(crate::cli::values::positive(crate::cli::values::MAX_MM))
        .collect()
}

/// Runs `converge`.
pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(args.frames > 0, "--frames must be at least 1");
    let ladder_mm = &args.ladder_mm;
    for &l in ladder_mm {
        anyhow::ensure!(
            l.is_finite() && l > args.fine_mm,
            "--ladder-mm {l}: each level must be coarser than --fine-mm ({})",
            args.fine_mm
        );
    }
    let check = args.check;
    let plan = Plan {
        frames: args.frames,
        fine_edge_m: args.fine_mm * 1e-3,
        reference: args.reference,
        check,
        modes: args.modes.clone(),
        twin_offset_m: (args.twin_mm > 0.0).then_some(args.twin_mm * 1e-3),
        ladder_m: ladder_mm.iter().map(|l| l * 1e-3).collect(),
        ladder_mode: args.ladder_mode,
        ladder_matched_thickness: !args.ladder_own_thickness_only,
        self_collision: args.self_collision,
    };
    std::fs::create_dir_all(&args.output)?;
    let mut tables = String::new();
    for shot in &args.shots {
        let (scene, name) = load(shot, &args)?;
        let dir = shot_dir(&args.output, &name);
        let report = converge(
            &scene,
            &name,
            &plan,
            &dir,
            args.coarse_mm * 1e-3,
            |spec, f, rec| {
                tracing::info!(
                    "{name}: {} frame {f}/{}: newton {}, cg {}, capped {}, substeps {}, {:.1} s",
                    spec.label(),
                    args.frames,
                    rec.newton_iters,
                    rec.cg_iters,
                    rec.capped_solves,
                    rec.substeps,
                    rec.wall_s
                )
            },
        )?;
        let base = args.modes.first().copied();
        let table = report.table(base);
        println!("{table}");
        tables.push_str(&table);
        tables.push('\n');
    }
    clothsr::io::write_atomic(&args.output.join("converge.md"), tables.as_bytes())?;
    Ok(())
}

/// A shot by file or by procedural name, with its name for the report.
fn load(shot: &str, args: &Args) -> anyhow::Result<(Scene, String)> {
    let path = PathBuf::from(shot);
    if !path.exists() {
        if let Some(mut scene) = catalogue::scene(shot, args.frames) {
            for c in args.inputs.collider.iter().chain(&args.inputs.avatar) {
                scene.add_collider_file(c)?;
            }
            return Ok((scene, shot.to_string()));
        }
    }
    let scene = args.inputs.load(&path)?;
    let name = path
        .file_stem()
        .map_or(shot.to_string(), |s| s.to_string_lossy().into_owned());
    Ok((scene, name))
}
