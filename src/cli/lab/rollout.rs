//! `clothsr lab rollout --model DIR --data DIR`: the corrector's rollout error against a data set's
//! M_int, beside the coarse simulation alone and the corrector without interleaving (see
//! [`clothsr::corrector::rollout`]).

use std::path::{Path, PathBuf};

use anyhow::Context;
use clothsr::corrector::data::Sequence;
use clothsr::corrector::rollout::{
    evaluate_from, evaluate_shifted, jitter_directions, sequence_distance_mm, HorizonErrors,
    RolloutErrors,
};
use clothsr::corrector::Corrector;
use clothsr::data::{coarse_simulation, read_manifest};
use clothsr::mesh::ClothMesh;
use clothsr::scene::Scene;
use nalgebra::Vector3;

/// Arguments of `rollout`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Corrector model directory (`clothsr lab train corrector`).
    #[arg(value_parser = crate::cli::values::input_dir, long)]
    model: PathBuf,
    /// Data set directory (`clothsr lab dataset`) with the ground truth; not one trained on.
    /// Repeat it for several held-out drops: each is rolled out and reported, then the errors
    /// are pooled over all their frames (one chaotic drop cannot rank two correctors).
    #[arg(value_parser = crate::cli::values::input_dir, long, required = true)]
    data: Vec<PathBuf>,
    /// Frames to roll out (default: all the data set has after the start).
    #[arg(long)]
    frames: Option<usize>,
    /// Start from the ground truth at the first step of this frame (1-based).
    #[arg(long, default_value_t = 1)]
    start_frame: usize,
    /// Write per-frame errors as CSV here (with `--horizon`: per frame after the start; with
    /// several `--data`, a first column names each row's data set).
    #[arg(value_parser = crate::cli::values::output_file, long)]
    csv: Option<PathBuf>,
    /// A second data set of the same scene and coarse mesh, started next to the first (a
    /// `clothsr lab dataset` run whose `--garment-offset` differs by a fraction of a millimetre,
    /// or a `clothsr lab fork` of the first: its shared frames count as zero, so start at the
    /// fork's frame): the distance between the two ground truths is reported beside the errors
    /// as the predictability floor, which no predictor of the first from its start can be
    /// expected to beat where the scene is chaotic (folds, contact and friction are).
    #[arg(value_parser = crate::cli::values::input_dir, long)]
    floor: Option<PathBuf>,
    /// Short-horizon mode: instead of one long rollout, roll out this many frames from the
    /// ground truth at every `--every`-th frame from the start and report the errors averaged
    /// per frame after the start.
    #[arg(long)]
    horizon: Option<usize>,
    /// The spacing of the short-horizon starts, frames.
    #[arg(long, default_value_t = 10)]
    every: usize,
    /// Run the corrector with this take-back scale instead of its model's (the gated
    /// decoder's share of each step's velocity change taken back is multiplied by it; in
    /// (0, 1]): to choose the value `train corrector --take-back` saves.
    #[arg(value_parser = crate::cli::values::positive(1.0), long)]
    take_back: Option<f64>,
    /// Run the corrector with this many rounds of smoothing of its correction instead of its
    /// model's (0: none): to choose the value `train corrector --smoothing` saves.
    #[arg(long)]
    smoothing: Option<usize>,
    // The coarse model of all three variants, in place of the one the corrector was trained
    // beside: to measure a corrector beside another coarse model without retraining it.
    #[command(flatten)]
    coarse: crate::cli::CoarseArgs,
    /// Roll each data set out this many more times, each from its start moved rigidly by
    /// `--jitter-mm` along another horizontal direction (the ground truth unchanged), and pool
    /// all the runs: where contact and folds make the coarse sheet's path chaotic, one
    /// rollout's ratio is one draw, the pooled one what the corrector gives on average.
    #[arg(long, default_value_t = 0)]
    jitter: usize,
    /// How far `--jitter` moves each start, mm.
    #[arg(value_parser = crate::cli::values::non_negative(crate::cli::values::MAX_MM), long, default_value_t = 0.1)]
    jitter_mm: f64,
}

/// Loads `--model` for `mesh` with the inference settings given on the command line.
fn load_corrector(args: &Args, mesh: &ClothMesh) -> anyhow::Result<Corrector> {
    let mut corrector = Corrector::load(&args.model, mesh)?;
    if let Some(k) = args.take_back {
        anyhow::ensure!(
            corrector.config.decoder.is_gated(),
            "--take-back: {} has a {:?} decoder, which takes nothing back",
            args.model.display(),
            corrector.config.decoder
        );
        corrector.config.take_back = k;
        corrector
            .config
            .check()
            .map_err(|e| anyhow::anyhow!("--take-back {k}: {e}"))?;
    }
    if let Some(n) = args.smoothing {
        corrector.config.smoothing = n;
    }
    let given = args.coarse.calibration();
    given.check_flags()?;
    let t = &mut corrector.training;
    if let Some(c) = given.replacing(&t.coarse) {
        t.coarse = c;
    }
    Ok(corrector)
}

/// Runs `rollout`.
pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(args.start_frame >= 1, "--start-frame counts from 1");
    anyhow::ensure!(
        args.jitter_mm.is_finite() && args.jitter_mm > 0.0,
        "--jitter-mm {}: the distance must be positive",
        args.jitter_mm
    );
    if let ([data], 0) = (args.data.as_slice(), args.jitter) {
        let (scene, frames) = open(&args, data)?;
        if let Some(horizon) = args.horizon {
            return short_horizons(&args, data, &scene, frames, horizon);
        }
        let (e, corrector, _) = long_rollout(&args, data, &scene, frames, 0)?;
        if let Some(csv) = &args.csv {
            clothsr::io::write_atomic(csv, e.csv().as_bytes())?;
        }
        report(&e, &corrector);
        return Ok(());
    }
    anyhow::ensure!(
        args.horizon.is_none() && args.floor.is_none(),
        "--horizon and --floor take one --data and no --jitter"
    );
    // Every data set is checked before the first rollout starts.
    let opened = args
        .data
        .iter()
        .map(|d| open(&args, d))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let mut runs = Vec::new();
    let mut csv = String::new();
    for (data, (scene, frames)) in args.data.iter().zip(opened) {
        for k in 0..=args.jitter {
            let (e, corrector, shift) = long_rollout(&args, data, &scene, frames, k)?;
            let mut name = data.display().to_string().replace(',', "_");
            if k == 0 {
                println!("== {}", data.display());
            } else {
                let d = shift / shift.norm();
                println!(
                    "== {}, start moved {} mm along ({:+.3}, {:+.3}, {:+.3})",
                    data.display(),
                    args.jitter_mm,
                    d.x,
                    d.y,
                    d.z
                );
                name += &format!("@{k}");
            }
            report(&e, &corrector);
            let table = e.csv();
            let mut lines = table.lines();
            let header = lines.next().unwrap_or_default();
            if csv.is_empty() {
                csv += &format!("data,{header}\n");
            }
            for line in lines {
                csv += &format!("{name},{line}\n");
            }
            runs.push(e);
        }
    }
    if let Some(path) = &args.csv {
        clothsr::io::write_atomic(path, csv.as_bytes())?;
    }
    let p = RolloutErrors::pooled(&runs);
    let ratios: Vec<String> = p.ratios.iter().map(|r| format!("{r:.2}×")).collect();
    let what = if args.jitter > 0 { "run" } else { "data set" };
    println!("== pooled over {} {what}s, {} frames", runs.len(), p.frames);
    println!("mean error, sim alone       {:.3} mm", p.sim_alone_mm);
    println!(
        "mean error, interleaved     {:.3} mm  ({:.2}× sim alone; per {what} {}, worst {:.2}×)",
        p.interleaved_mm,
        p.ratio(),
        ratios.join(", "),
        p.worst_ratio()
    );
    let range = |f: fn(&RolloutErrors) -> f64| {
        let v: Vec<f64> = runs.iter().map(f).collect();
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        (lo, v.iter().copied().fold(f64::NEG_INFINITY, f64::max))
    };
    let (a, b) = (range(|e| e.means().0), range(|e| e.means().1));
    println!(
        "range over {what}s          sim alone {:.3}–{:.3} mm, interleaved {:.3}–{:.3} mm",
        a.0, a.1, b.0, b.1
    );
    Ok(())
}

/// The scene of data set `data` and the frames to roll out of it.
fn open(args: &Args, data: &Path) -> anyhow::Result<(Scene, usize)> {
    let m = read_manifest(data)?;
    let frames = args
        .frames
        .unwrap_or(m.frames_done.saturating_sub(args.start_frame));
    anyhow::ensure!(
        frames > 0 && args.start_frame + frames <= m.frames_done,
        "{}: the data set has {} frames: too few to roll out {frames} from frame {}",
        data.display(),
        m.frames_done,
        args.start_frame
    );
    let source = m.source.as_ref().with_context(|| {
        format!(
            "{}: the data set does not record its scene files",
            data.join("manifest.json").display()
        )
    })?;
    Ok((source.load()?, frames))
}

/// One long rollout of `frames` from `--start-frame` on `data`, with the floor when asked;
/// `jitter` k > 0: from the start moved by `--jitter-mm` along the k-th of `--jitter`
/// horizontal directions. Returns the errors, the corrector and the start's shift, m.
fn long_rollout(
    args: &Args,
    data: &Path,
    scene: &Scene,
    frames: usize,
    jitter: usize,
) -> anyhow::Result<(RolloutErrors, Corrector, Vector3<f64>)> {
    let mut sim = coarse_simulation(scene, data, args.start_frame)?;
    let t0 = sim.state.t_s;
    let seq = Sequence::load(
        data,
        Some(args.start_frame..=args.start_frame + frames),
        &sim,
    )?;
    let corrector = load_corrector(args, &seq.mesh)?;
    let mut alone = coarse_simulation(scene, data, args.start_frame)?;
    let mut check = coarse_simulation(scene, data, args.start_frame)?;
    for s in [&mut sim, &mut alone, &mut check] {
        corrector.training.prepare_coarse(s)?;
    }
    let shift = match jitter {
        0 => Vector3::zeros(),
        k => {
            jitter_directions(sim.sim.params.gravity_m_s2, args.jitter)
                .get(k - 1)
                .copied()
                .with_context(|| {
                    format!(
                        "{}: the scene has no gravity to jitter across",
                        data.display()
                    )
                })?
                * (args.jitter_mm * 1e-3)
        }
    };
    let mut e = evaluate_shifted(
        &seq,
        0,
        shift,
        [&mut alone, &mut sim, &mut check],
        t0,
        &corrector,
        frames,
        |f, a, b, c| {
            if f.is_multiple_of(10) {
                tracing::info!(
                "frame {f}: sim alone {a:.3} mm, interleaved {b:.3} mm, not interleaved {c:.3} mm"
            );
            }
        },
    )?;
    if let Some(dir) = &args.floor {
        let other = Sequence::load(
            dir,
            Some(args.start_frame..=args.start_frame + frames),
            &sim,
        )?;
        e.floor_mm = sequence_distance_mm(&seq, &other, &e.frame)?;
    }
    Ok((e, corrector, shift))
}

/// Prints one rollout's summary.
fn report(e: &RolloutErrors, corrector: &Corrector) {
    let (a, b, c) = e.means();
    println!("frames                      {}", e.frame.len());
    println!("{} (all three variants)", coarse_setup(&corrector.training));
    if let Some(f) = e.diverged_at_frame {
        println!("interleaved rollout DIVERGED in frame {f}: the corrector's output left its training range");
    }
    println!("mean error, sim alone       {a:.3} mm");
    println!(
        "mean error, interleaved     {b:.3} mm  ({:.2}× sim alone)",
        b / a
    );
    println!(
        "mean error, not interleaved {c:.3} mm  ({:.2}× sim alone)",
        c / a
    );
    if let Some(f) = e.floor_mean() {
        println!(
            "predictability floor        {f:.3} mm  (the two ground truths' distance; sim alone {:.2}×, interleaved {:.2}× it)",
            a / f,
            b / f
        );
    }
    let [sg, sa, si] = e.strain_means();
    println!(
        "mean edge strain            ground truth {sg:+.3} %, sim alone {sa:+.3} %, interleaved {si:+.3} %"
    );
    let [oa, oi] = e.offset_means();
    println!(
        "rigid part of the error     sim alone {oa:.3} mm, interleaved {oi:.3} mm (|mean of x − x_gt|)"
    );
    let (u, c) = e.one_step_means();
    println!(
        "one step: M_c → M_int      {u:.4} mm uncorrected, {c:.4} mm corrected ({:.2}×)",
        c / u
    );
    println!(
        "interleaved trend           {:+.3} mm per 100 frames",
        e.interleaved_trend_mm_per_100()
    );
    println!(
        "coarse step {:.2} ms, corrector {:.2} ms per step ({:.2}×)",
        e.sim_step_ms,
        e.corrector_ms,
        e.corrector_ms / e.sim_step_ms
    );
    let (prox, feat, net) = corrector.times.mean_ms();
    println!(
        "corrector per call: body proximity {prox:.2} ms, features {feat:.2} ms, network {net:.2} ms"
    );
}

/// `--horizon`: rollouts of `horizon` frames from the ground truth at every `--every`-th frame
/// of the `frames` from `--start-frame`, each with fresh simulators, averaged per frame after
/// the start.
fn short_horizons(
    args: &Args,
    data: &Path,
    scene: &Scene,
    frames: usize,
    horizon: usize,
) -> anyhow::Result<()> {
    anyhow::ensure!(
        horizon > 0 && args.every > 0 && horizon <= frames,
        "--horizon ({horizon}) and --every ({}) must be positive and the horizon at most the \
         {frames} frames rolled over",
        args.every
    );
    let last = args.start_frame + frames;
    let starts: Vec<usize> = (args.start_frame..=last - horizon)
        .step_by(args.every)
        .collect();
    let make = |f: usize| coarse_simulation(scene, data, f);
    let probe = make(args.start_frame)?;
    let seq = Sequence::load(data, Some(args.start_frame..=last), &probe)?;
    let corrector = load_corrector(args, &seq.mesh)?;
    let s = seq.manifest.steps_per_frame;
    let mut runs = Vec::new();
    for &start in &starts {
        let mut sims = [make(start)?, make(start)?, make(start)?];
        let t0 = sims[0].state.t_s;
        for sim in &mut sims {
            corrector.training.prepare_coarse(sim)?;
        }
        let [a, b, c] = &mut sims;
        let e = evaluate_from(
            &seq,
            (start - args.start_frame) * s,
            [a, b, c],
            t0,
            &corrector,
            horizon,
            |_, _, _, _| {},
        )?;
        let (x, y, _) = e.means();
        tracing::info!("from frame {start}: sim alone {x:.3} mm, interleaved {y:.3} mm");
        runs.push(e);
    }
    let h = HorizonErrors::from_runs(&starts, &runs, horizon)?;
    if let Some(csv) = &args.csv {
        clothsr::io::write_atomic(csv, h.csv().as_bytes())?;
    }
    println!(
        "{} rollouts of {horizon} frames, from frames {}..={} every {}",
        starts.len(),
        starts[0],
        starts[starts.len() - 1],
        args.every
    );
    println!("{} (both variants)", coarse_setup(&corrector.training));
    println!("frames after start   sim alone mm   interleaved mm   ratio");
    for k in 0..horizon {
        println!(
            "{:>18}   {:>12.3}   {:>14.3}   {:.2}×",
            k + 1,
            h.sim_alone_mm[k],
            h.interleaved_mm[k],
            h.interleaved_mm[k] / h.sim_alone_mm[k]
        );
    }
    Ok(())
}

/// The coarse simulator's settings a corrector runs beside: its membrane's compression factor,
/// its friction coefficient against bodies and, when not the simulator's, its wrinkle bending
/// gain, bending factor and crease contacts.
fn coarse_setup(t: &clothsr::corrector::training::TrainingConfig) -> String {
    let c = &t.coarse;
    let wrinkles = c
        .wrinkle_bending
        .map_or_else(String::new, |g| format!(", wrinkle bending {g}"));
    let bending = c
        .bending
        .map_or_else(String::new, |b| format!(", bending {b}"));
    let creases = if c.crease_contacts == Some(false) {
        ", no crease contacts"
    } else {
        ""
    };
    format!(
        "coarse membrane compression {}, friction {}{wrinkles}{bending}{creases}",
        c.compression.unwrap_or(1.0),
        c.friction_label()
    )
}
