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
    /// Frames to roll out (default: all the data set has).
    #[arg(long)]
    frames: Option<usize>,
    /// Write per-frame errors as CSV here.
    #[arg(long)]
    csv: Option<PathBuf>,
}

/// Runs `rollout`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let m = read_manifest(&args.data)?;
    let frames = args.frames.unwrap_or(m.frames_done.saturating_sub(1));
    anyhow::ensure!(frames > 0, "the data set has too few frames to roll out");
    let source = m.source.as_ref().with_context(|| {
        format!(
            "{}: the data set does not record its scene files",
            args.data.join("manifest.json").display()
        )
    })?;
    let scene = source.load()?;
    let mut sim = coarse_simulation(&scene, &args.data, 1)?;
    let t0 = sim.state.t_s;
    let seq = Sequence::load(
        &args.data,
        Some(1..=(frames + 1).min(m.frames_done)),
        &sim.colliders,
        t0,
    )?;
    let corrector = Corrector::load(&args.model, &seq.mesh)?;
    let e = evaluate(&seq, &mut sim, t0, &corrector, frames, |f, a, b, c| {
        if f.is_multiple_of(10) {
            tracing::info!(
                "frame {f}: sim alone {a:.3} mm, interleaved {b:.3} mm, not interleaved {c:.3} mm"
            );
        }
    })?;
    if let Some(csv) = &args.csv {
        clothsr::io::write_atomic(csv, e.csv().as_bytes())?;
    }
    let (a, b, c) = e.means();
    println!("frames                      {}", e.frame.len());
    println!("mean error, sim alone       {a:.3} mm");
    println!(
        "mean error, interleaved     {b:.3} mm  ({:.2}× sim alone)",
        b / a
    );
    println!(
        "mean error, not interleaved {c:.3} mm  ({:.2}× sim alone)",
        c / a
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
    Ok(())
}
