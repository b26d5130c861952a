//! `clothsr run SCENE… (-o OUT.usdc | --out-dir DIR) [--models DIR]`: the whole pipeline (see
//! [`clothsr::pipeline`]) — coarse simulation, corrector, mesh super-resolution — writing the
//! fine garments as time-sampled points frame by frame, with an optional Rerun recording. A
//! killed run continues from its last published frame when called again with the same settings.
//! `lab run` adds the pipeline's research settings ([`Knobs`]).

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clothsr::pipeline::shot::{
    run_shot, ErrorSummary, OutputKind, RunModels, RunSummary, ShotFiles, ShotSummary, Status,
    DEFAULT_CLIP_FRAMES,
};
use clothsr::pipeline::{CoarseCalibration, CorrectorChoice, Options, Progress, Report};
use clothsr::sim::step::SolverMode;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};

/// Arguments of `run`: what a user needs.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scenes: USD (garments, colliders, solver), GarmentCode JSON or OBJ cloth. Several need
    /// --out-dir.
    #[arg(required = true)]
    scenes: Vec<PathBuf>,
    #[command(flatten, next_help_heading = "Input")]
    inputs: super::SceneInputs,
    /// Output USD file of a single scene: the fine garments (and the colliders), one time
    /// sample per frame.
    #[arg(value_parser = crate::cli::values::output_usd, short, long, conflicts_with = "out_dir", help_heading = "Output")]
    output: Option<PathBuf>,
    /// Output folder for several scenes: DIR/<scene name>.usdc (and .rrd with --rrd). Each
    /// scene runs in its own process; the batch goes on past one that fails.
    #[arg(value_parser = crate::cli::values::input_dir, long, help_heading = "Output")]
    out_dir: Option<PathBuf>,
    /// Frames to run (default: the scene's frame range).
    #[arg(long, help_heading = "Output")]
    frames: Option<usize>,
    /// Write text USD even for a .usd file.
    #[arg(long, help_heading = "Output")]
    ascii: bool,
    /// `on`: an override layer for the USD shot: over the shot, it replaces each garment with
    /// its fine animated mesh at the garment's own prim, in the shot's units, up axis and time
    /// codes, copying nothing else; <output stem>.composed.usda beside it is the shot with the
    /// layer over it, to open or import. `off`: a standalone stage, the fine garments
    /// under /World/Garments and the colliders, in metres with y up. `auto`: on for USD input.
    #[arg(
        long,
        value_enum,
        hide_possible_values = true,
        value_name = "auto|on|off",
        default_value = "auto",
        num_args = 0..=1,
        default_missing_value = "on",
        help_heading = "Output"
    )]
    layer: OutputKind,
    /// Frames per value clip of a layered output: a longer shot goes to one file per clip in
    /// <output>.clips/, stitched by the output layer (0: every frame in one file).
    #[arg(long, default_value_t = DEFAULT_CLIP_FRAMES, help_heading = "Output")]
    clip_frames: usize,
    /// Start over even when an interrupted run with the same settings left a resume point.
    #[arg(long, help_heading = "Output")]
    restart: bool,
    /// Models folder: `isr/` (required), `corrector/` and `coarse.json` (optional), and
    /// `models.json`, the held-out figures each path through them was validated with.
    /// Default: the generic models ($CLOTHSR_MODELS, else `models/generic` beside the
    /// executable or in the source tree it was built from).
    #[arg(value_parser = crate::cli::values::input_dir, long, help_heading = "Models")]
    models: Option<PathBuf>,
    /// Whether the corrector runs: `auto` takes the path the folder's models.json validated
    /// as better (the corrector where a folder without one has it), `on` or `off` forces it.
    #[arg(
        long,
        value_enum,
        hide_possible_values = true,
        value_name = "auto|on|off",
        default_value = "auto",
        help_heading = "Models"
    )]
    corrector: CorrectorChoice,
    /// Save a Rerun recording (colliders, coarse and fine meshes, stage timings on a frame
    /// timeline): to FILE.rrd, or without a value beside each output as <name>.rrd. Open it
    /// with `rerun FILE.rrd` (pip install rerun-sdk==0.36.3).
    #[arg(value_parser = crate::cli::values::output_file_or_default, long, num_args = 0..=1, default_missing_value = "", help_heading = "Preview")]
    rrd: Option<PathBuf>,
    /// Stream live to a Rerun viewer (started if none runs; needs `rerun` on the PATH).
    #[arg(long, conflicts_with = "rrd", help_heading = "Preview")]
    spawn: bool,
    /// A fine simulation of the same scene (USD, or a `clothsr lab dataset` directory): the
    /// Rerun preview then colours the fine mesh by its distance to it and plots the mean.
    #[arg(value_parser = crate::cli::values::input, long, help_heading = "Preview")]
    gt: Option<PathBuf>,
    /// Run only this shot of the batch (the batch runs each shot in a child process).
    #[arg(long, hide = true)]
    batch_shot: Option<usize>,
}

/// Arguments of `lab run`: the same, and every research setting of the pipeline.
#[derive(Debug, clap::Args)]
pub struct LabArgs {
    #[command(flatten)]
    user: Args,
    #[command(flatten, next_help_heading = "Research")]
    knobs: Knobs,
}

/// The pipeline's research settings (`lab run`): each unset leaves [`Options::default`]'s
/// value, which a user's `run` takes.
#[derive(Debug, Default, clap::Args)]
pub struct Knobs {
    /// Distance shown red in the --gt heat map, mm [default: 5].
    #[arg(long, value_parser = crate::cli::values::positive(crate::cli::values::MAX_MM))]
    heat_max_mm: Option<f64>,
    /// Also write the coarse mesh the MSR module saw (M_int, or M_c without corrector).
    #[arg(long, value_parser = crate::cli::values::output_usd)]
    coarse_out: Option<PathBuf>,
    /// Also write the coarse mesh upsampled to the fine mesh (the baseline without learned
    /// detail), for `clothsr eval --baseline`.
    #[arg(long, value_parser = crate::cli::values::output_usd)]
    upsampled_out: Option<PathBuf>,
    /// Coarse edge length, millimetres [default: 20].
    #[arg(long, value_parser = crate::cli::values::positive(crate::cli::values::MAX_MM))]
    coarse_mm: Option<f64>,
    #[command(flatten)]
    variation: super::VariationArgs,
    /// Skip sewing and settling garments with seams before the first frame.
    #[arg(long)]
    no_dress: bool,
    /// Iterate Newton to convergence every coarse step instead of the fast one-step solver the
    /// sample models were trained beside.
    #[arg(long)]
    converged: bool,
    /// Cloth self-collision in the coarse simulation, `on` or `off` [default: off].
    #[arg(long, value_name = "on|off", value_parser = crate::cli::values::on_off(), action = clap::ArgAction::Set)]
    self_collision: Option<bool>,
    // The coarse model (unset: the corrector's, else the models folder's `coarse.json`'s, else
    // the simulator's; a corrector trained beside another is an error).
    #[command(flatten)]
    coarse: super::CoarseArgs,
    /// Seconds between publishing the output and the resume point while running (0: every
    /// frame, as the fault tests kill runs).
    #[arg(long, value_parser = crate::cli::values::non_negative(crate::cli::values::MAX_S))]
    publish_every_s: Option<f64>,
    /// Write the MSR module's fine meshes as the network gives them. By default every fine
    /// vertex found inside a collider, or nearer it than half the fine simulation's contact
    /// thickness, is moved out to that distance (the 20 mm mesh's chords and the network's
    /// wrinkles cut into a body the cloth wraps)
    #[arg(long)]
    no_push_out: bool,
}

/// One scene's files.
struct Job {
    scene: PathBuf,
    output: PathBuf,
    rrd: Option<PathBuf>,
}

fn jobs(args: &Args, knobs: &Knobs) -> anyhow::Result<Vec<Job>> {
    let rrd_beside = |out: &Path| out.with_extension("rrd");
    match (&args.output, &args.out_dir) {
        (Some(out), None) => {
            anyhow::ensure!(
                args.scenes.len() == 1,
                "-o names one output but {} scenes were given: use --out-dir DIR",
                args.scenes.len()
            );
            let output = super::check_output(&args.scenes[0], out)?;
            let rrd = args.rrd.as_ref().map(|r| {
                if r.as_os_str().is_empty() {
                    rrd_beside(&output)
                } else {
                    r.clone()
                }
            });
            Ok(vec![Job {
                scene: args.scenes[0].clone(),
                output,
                rrd,
            }])
        }
        (None, Some(dir)) => {
            anyhow::ensure!(
                dir.is_dir(),
                "{}: the output folder does not exist",
                dir.display()
            );
            anyhow::ensure!(
                args.rrd.as_ref().is_none_or(|r| r.as_os_str().is_empty()),
                "with --out-dir, give --rrd without a file: each scene's recording goes beside its USD"
            );
            anyhow::ensure!(
                knobs.coarse_out.is_none() && knobs.upsampled_out.is_none(),
                "--coarse-out and --upsampled-out name one file: run scenes one at a time for them"
            );
            let mut seen = std::collections::HashSet::new();
            args.scenes
                .iter()
                .map(|s| {
                    let output = clothsr::pipeline::shot::shot_output(s, dir)
                        .with_context(|| format!("{}: no file name", s.display()))?;
                    anyhow::ensure!(
                        seen.insert(output.clone()),
                        "two scenes are named '{}': their outputs would collide in {}",
                        s.file_stem().unwrap_or_default().to_string_lossy(),
                        dir.display()
                    );
                    let output = super::check_output(s, &output)?;
                    Ok(Job {
                        scene: s.clone(),
                        rrd: args.rrd.as_ref().map(|_| rrd_beside(&output)),
                        output,
                    })
                })
                .collect()
        }
        _ => anyhow::bail!("give the output: -o OUT.usdc (one scene) or --out-dir DIR"),
    }
}

/// Runs `run`: every shot, going on past a failing one; the summary says what each did.
pub fn run(args: Args) -> anyhow::Result<RunSummary> {
    run_with(args, Knobs::default())
}

/// Runs `lab run`.
pub fn run_lab(args: LabArgs) -> anyhow::Result<RunSummary> {
    run_with(args.user, args.knobs)
}

impl Knobs {
    /// The run's options: the defaults with what these flags set.
    fn options(&self) -> Options {
        let d = Options::default();
        Options {
            coarse_edge_m: self.coarse_mm.map_or(d.coarse_edge_m, |mm| mm * 1e-3),
            coarse_solver: if self.converged {
                SolverMode::Converged
            } else {
                d.coarse_solver
            },
            self_collision: self.self_collision.unwrap_or(d.self_collision),
            match_contact_thickness: d.match_contact_thickness,
            dress: d.dress && !self.no_dress,
            coarse: self.coarse.calibration(),
            push_out: d.push_out && !self.no_push_out,
            variation: self.variation.variation(),
        }
    }
}

fn run_with(args: Args, knobs: Knobs) -> anyhow::Result<RunSummary> {
    let models_dir = match &args.models {
        Some(m) => m.clone(),
        None => clothsr::pipeline::models::find_generic_models()?,
    };
    anyhow::ensure!(
        args.gt.is_none() || args.rrd.is_some() || args.spawn,
        "--gt colours the Rerun preview: give --rrd or --spawn with it (clothsr eval measures files)"
    );
    let mut jobs = jobs(&args, &knobs)?;
    let models = RunModels::load(&models_dir, args.corrector, knobs.options())?;
    if let Some(k) = args.batch_shot {
        anyhow::ensure!(
            k < jobs.len(),
            "--batch-shot {k}: the batch has {} shots",
            jobs.len()
        );
        jobs = vec![jobs.swap_remove(k)];
    } else if jobs.len() > 1 && cfg!(target_os = "linux") {
        return run_isolated(&jobs);
    }
    tracing::info!("path: {}", models.why);
    if models.calibration.is_some() {
        tracing::info!(
            "coarse model: {} ({} under the options given)",
            models.opts.coarse,
            models_dir.join(CoarseCalibration::FILE).display()
        );
    }
    let multi = MultiProgress::new();
    let overall = (jobs.len() > 1).then(|| {
        let b = multi.add(ProgressBar::new(jobs.len() as u64));
        b.set_style(
            ProgressStyle::with_template("{bar:30} {pos}/{len} scenes {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        b
    });
    let mut shots = Vec::new();
    for job in &jobs {
        if let Some(o) = &overall {
            o.set_message(job.scene.display().to_string());
        }
        let t0 = std::time::Instant::now();
        let outcome = run_one(&args, &knobs, job, &models, &multi).map_err(|e| {
            // Name the shot where the error does not already.
            if format!("{e:#}").contains(&job.scene.display().to_string()) {
                e
            } else {
                e.context(job.scene.display().to_string())
            }
        });
        let (status, report, error) = match outcome {
            Ok(r) => (Status::Ok, Some(r), None),
            Err(err) => {
                // A batch goes on: the error is reported here and in the summary.
                eprintln!("error: {err:#}");
                let error = ErrorSummary {
                    kind: super::error_kind(&err),
                    message: format!("{err:#}"),
                };
                (Status::Failed, None, Some(error))
            }
        };
        shots.push(ShotSummary {
            scene: job.scene.clone(),
            output: job.output.clone(),
            status,
            frames_computed: report.map_or(0, |r| r.frames_computed),
            resumed_after: report.and_then(|r| r.resumed_after),
            wall_s: t0.elapsed().as_secs_f64(),
            error,
        });
        if let Some(o) = &overall {
            o.inc(1);
        }
    }
    if let Some(o) = overall {
        o.finish();
    }
    let failed = shots.iter().filter(|s| s.error.is_some()).count();
    if failed > 0 && shots.len() > 1 {
        tracing::error!("{failed} of {} shots failed", shots.len());
    }
    Ok(RunSummary::of(shots, None))
}

/// Runs a batch with each shot in a child process (this executable again, given the same
/// arguments and `--batch-shot K`): a shot whose file crashes a native library (usd-core's
/// parser overflowing its stack on a deeply nested layer, say) fails alone, and the batch goes
/// on. The children print their progress; each hands its summary back as JSON.
fn run_isolated(jobs: &[Job]) -> anyhow::Result<RunSummary> {
    let exe = std::env::current_exe().context("cannot find this executable to run each shot")?;
    let argv: Vec<std::ffi::OsString> = std::env::args_os().skip(1).collect();
    let mut shots = Vec::with_capacity(jobs.len());
    for (k, job) in jobs.iter().enumerate() {
        tracing::info!("shot {}/{}: {}", k + 1, jobs.len(), job.scene.display());
        let t0 = std::time::Instant::now();
        let mut child = std::process::Command::new(&exe);
        child.args(&argv).arg("--batch-shot").arg(k.to_string());
        if !argv.iter().any(|a| a == "--json") {
            child.arg("--json");
        }
        child
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::inherit());
        die_with_parent(&mut child);
        let out = child
            .output()
            .with_context(|| format!("cannot start the process for {}", job.scene.display()))?;
        let reported = String::from_utf8_lossy(&out.stdout)
            .lines()
            .rev()
            .find_map(|l| serde_json::from_str::<RunSummary>(l).ok());
        let failed = |error: ErrorSummary| ShotSummary {
            scene: job.scene.clone(),
            output: job.output.clone(),
            status: Status::Failed,
            frames_computed: 0,
            resumed_after: None,
            wall_s: t0.elapsed().as_secs_f64(),
            error: Some(error),
        };
        let shot = match reported {
            Some(mut r) if r.shots.len() == 1 => r.shots.swap_remove(0),
            // The child failed before its shot (its error printed above).
            Some(RunSummary { error: Some(e), .. }) => failed(e),
            _ => {
                let message = format!(
                    "{}: the process running this shot {}, with no result: a native library \
                     (usd-core, say) crashed on it; the other shots go on",
                    job.scene.display(),
                    how_it_ended(&out.status)
                );
                eprintln!("error: {message}");
                failed(ErrorSummary {
                    kind: clothsr::ErrorKind::Failure,
                    message,
                })
            }
        };
        shots.push(shot);
    }
    let failed = shots.iter().filter(|s| s.error.is_some()).count();
    if failed > 0 {
        tracing::error!("{failed} of {} shots failed", shots.len());
    }
    Ok(RunSummary::of(shots, None))
}

/// "was killed by signal 11 (SIGSEGV)", "exited with code 101".
fn how_it_ended(status: &std::process::ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match (status.code(), status.signal()) {
        (_, Some(sig)) => {
            let name = match sig {
                libc::SIGSEGV => " (SIGSEGV)",
                libc::SIGABRT => " (SIGABRT)",
                libc::SIGBUS => " (SIGBUS)",
                libc::SIGKILL => " (SIGKILL)",
                libc::SIGILL => " (SIGILL)",
                libc::SIGFPE => " (SIGFPE)",
                _ => "",
            };
            format!("was killed by signal {sig}{name}")
        }
        (Some(code), None) => format!("exited with code {code}"),
        (None, None) => "ended".into(),
    }
}

/// Asks the kernel to kill the child when this process ends (Linux), so that a batch that is
/// itself killed leaves no shot running behind it.
#[allow(unsafe_code)]
fn die_with_parent(child: &mut std::process::Command) {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::process::CommandExt;
        // SAFETY: `prctl` is async-signal-safe and touches no memory of ours.
        unsafe {
            child.pre_exec(|| {
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
    }
}

fn run_one(
    args: &Args,
    knobs: &Knobs,
    job: &Job,
    models: &RunModels,
    multi: &MultiProgress,
) -> anyhow::Result<Report> {
    let source = args.inputs.source(&job.scene);
    let files = ShotFiles {
        output: job.output.clone(),
        coarse: knobs.coarse_out.clone(),
        upsampled: knobs.upsampled_out.clone(),
        rrd: job.rrd.clone(),
        spawn: args.spawn,
        ground_truth: args.gt.clone(),
        ascii: args.ascii,
        restart: args.restart,
        kind: args.layer,
        clip_frames: args.clip_frames,
        publish_every_s: knobs.publish_every_s,
        heat_max_m: knobs.heat_max_mm.map(|mm| mm * 1e-3),
    };
    let bar = multi.add(ProgressBar::new(0));
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} frames {per_sec} eta {eta} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let report = run_shot(models, &source, &files, args.frames, |g: &Progress| {
        show_progress(&bar, g)
    });
    let report = match report {
        Ok(r) => r,
        Err(e) => {
            bar.abandon();
            if !job.output.exists() {
                return Err(e.into());
            }
            return Err(e).with_context(|| {
                format!(
                    "{} keeps the frames published before the failure; run again to resume",
                    job.output.display()
                )
            });
        }
    };
    bar.finish();
    log_report(&job.output, &report.run);
    // Written after the layer: one older than the output is another run's.
    let composed = clothsr::io::usd::composed_path(&job.output);
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    if modified(&composed).is_some() && modified(&composed) >= modified(&job.output) {
        tracing::info!("the shot with its fine cloth: {}", composed.display());
    }
    Ok(report.run)
}

/// Moves the progress bar to frame `g` with its stage times (logged instead without a
/// terminal).
fn show_progress(bar: &ProgressBar, g: &Progress) -> ControlFlow<()> {
    if g.frame == 0 || Some(g.frame) == g.resumed_after {
        bar.set_length(g.frames as u64);
        bar.set_position(g.frame as u64);
        bar.reset_eta();
        return ControlFlow::Continue(());
    }
    let t = g.times;
    let mut message = format!(
        "frame {}/{}: simulator {:.2} s, corrector {:.2} s, MSR {:.2} s",
        g.frame, g.frames, t.simulator_s, t.corrector_s, t.msr_s
    );
    if g.pushed.inside > 0 {
        message += &format!(
            ", {} fine vertices pushed out of bodies (deepest {:.1} mm; {} where a body overlaps \
             itself)",
            g.pushed.inside,
            g.pushed.max_depth_m * 1e3,
            g.pushed.in_overlap
        );
    }
    if bar.is_hidden() {
        tracing::info!("{message}");
    }
    bar.set_message(message);
    bar.set_position(g.frame as u64);
    ControlFlow::Continue(())
}

/// Logs what a finished run wrote to `output`: frames, time per stage, vertices pushed out.
fn log_report(output: &Path, report: &Report) {
    let n = report.frames_computed.max(1) as f64;
    let t = report.totals;
    tracing::info!(
        "wrote {}: {} frames in {:.1} s{}; per frame: simulator {:.3} s, corrector {:.3} s, MSR {:.3} s",
        output.display(),
        report.frames_computed,
        report.wall_s,
        report
            .resumed_after
            .map(|f| format!(" (resumed after frame {f})"))
            .unwrap_or_default(),
        t.simulator_s / n,
        t.corrector_s / n,
        t.msr_s / n
    );
    if report.pushed.moved > 0 {
        tracing::info!(
            "fine vertices pushed out of the colliders: {:.0} a frame inside one (deepest {:.1} mm; {:.0} where a collider overlaps itself), {:.0} more nearer than the clearance",
            report.pushed.inside as f64 / n,
            report.pushed.max_depth_m * 1e3,
            report.pushed.in_overlap as f64 / n,
            (report.pushed.moved - report.pushed.inside) as f64 / n
        );
    }
}
