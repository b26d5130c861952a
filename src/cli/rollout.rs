//! `clothsr rollout --model DIR --data DIR`: the corrector's rollout error against a data set's
//! M_int, beside the coarse simulation alone and the corrector without interleaving (see
//! [`clothsr::corrector::rollout`]).

use std::path::PathBuf;

use anyhow::Context;
use clothsr::corrector::data::Sequence;
use clothsr::corrector::rollout::evaluate;
use clothsr::corrector::Corrector;
use clothsr::data::{coarse_simulation, read_manifest};

/// Arguments of `rollout`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Corrector model directory (`clothsr train corrector`).
    #[arg(long)]
    model: PathBuf,
    /// Data set directory (`clothsr dataset`) with the ground truth; not one trained on.
    #[arg(long)]
    data: PathBuf,
    /// Frames to roll out (default: all the data set has after the start).
    #[arg(long)]
    frames: Option<usize>,
    /// Start from the ground truth at the first step of this frame (1-based).
    #[arg(long, default_value_t = 1)]
    start_frame: usize,
    /// Write per-frame errors as CSV here.
    #[arg(long)]
    csv: Option<PathBuf>,
}

/// Runs `rollout`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let m = read_manifest(&args.data)?;
    anyhow::ensure!(args.start_frame >= 1, "--start-frame counts from 1");
    let frames = args
        .frames
        .unwrap_or(m.frames_done.saturating_sub(args.start_frame));
    anyhow::ensure!(
        frames > 0 && args.start_frame + frames <= m.frames_done,
        "the data set has {} frames: too few to roll out {frames} from frame {}",
        m.frames_done,
        args.start_frame
    );
    let source = m.source.as_ref().with_context(|| {
        format!(
            "{}: the data set does not record its scene files",
            args.data.join("manifest.json").display()
        )
    })?;
    let scene = source.load()?;
    let mut sim = coarse_simulation(&scene, &args.data, args.start_frame)?;
    let t0 = sim.state.t_s;
    let seq = Sequence::load(
        &args.data,
        Some(args.start_frame..=args.start_frame + frames),
        &sim,
    )?;
    let corrector = Corrector::load(&args.model, &seq.mesh)?;
    let mut alone = coarse_simulation(&scene, &args.data, args.start_frame)?;
    let mut check = coarse_simulation(&scene, &args.data, args.start_frame)?;
    for s in [&mut sim, &mut alone, &mut check] {
        corrector.training.prepare_coarse(s)?;
    }
    let e = evaluate(
        &seq,
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
    if let Some(csv) = &args.csv {
        clothsr::io::write_atomic(csv, e.csv().as_bytes())?;
    }
    let (a, b, c) = e.means();
    println!("frames                      {}", e.frame.len());
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
    Ok(())
}
