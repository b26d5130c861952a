//! `clothsr lab sr --model DIR --data DIR`: super-resolves a data set's M_int sequence with an ISR
//! model and measures the fine meshes against the fine simulation, beside the upsampled coarse
//! mesh (see [`clothsr::msr::eval`]).

use std::fmt::Write as _;
use std::path::PathBuf;

use clothsr::data::read_manifest;
use clothsr::msr::data::IsrSequence;
use clothsr::msr::eval::evaluate;
use clothsr::msr::Isr;

/// Arguments of `sr`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// ISR model directory (`clothsr lab train isr`).
    #[arg(value_parser = crate::cli::values::input_dir, long)]
    model: PathBuf,
    /// Data set directory (`clothsr lab dataset`) with the ground truth; not one trained on.
    #[arg(value_parser = crate::cli::values::input_dir, long)]
    data: PathBuf,
    /// First frame (1-based); it starts from the coarse map, as a new shot.
    #[arg(long, default_value_t = 1)]
    start_frame: usize,
    /// Frames to super-resolve (default: all from the start).
    #[arg(long)]
    frames: Option<usize>,
    /// Initialise every frame with the fine simulation's previous frame instead of the
    /// network's own output (a diagnostic).
    #[arg(long)]
    teacher_forcing: bool,
    /// Write per-frame errors and times as CSV here.
    #[arg(value_parser = crate::cli::values::output_file, long)]
    csv: Option<PathBuf>,
}

/// Runs `sr`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let m = read_manifest(&args.data)?;
    anyhow::ensure!(args.start_frame >= 1, "--start-frame counts from 1");
    anyhow::ensure!(
        args.start_frame <= m.frames_done,
        "{} has {} frames; --start-frame {} is past its end",
        args.data.display(),
        m.frames_done,
        args.start_frame
    );
    let last = args.frames.map_or(m.frames_done, |n| {
        (args.start_frame + n.max(1) - 1).min(m.frames_done)
    });
    let isr = Isr::load(&args.model)?;
    anyhow::ensure!(
        (isr.cfg.pixel_m - m.fine_edge_m).abs() < 1e-9,
        "the model works at {} mm pixels but {} was simulated at {} mm",
        isr.cfg.pixel_m * 1e3,
        args.data.display(),
        m.fine_edge_m * 1e3
    );
    let seq = IsrSequence::load(
        &args.data,
        Some(args.start_frame..=last),
        isr.cfg.pixel_m,
        isr.cfg.phong_alpha,
        0.0,
    )?;
    let e = evaluate(&seq, &isr, args.teacher_forcing, |k, n| {
        if k.is_multiple_of(10) {
            tracing::info!("frame {k}/{n}");
        }
        std::ops::ControlFlow::Continue(())
    })?;
    if let Some(csv) = &args.csv {
        let mut text = String::from(
            "frame,sr_mm,sr_max_mm,upsampled_mm,phong_mm,sr_normal_deg,phong_normal_deg,sr_bend_w1_deg,upsampled_bend_w1_deg,sr_jitter_mm,phong_jitter_mm,gt_jitter_mm,\
             sr_jitter_error_mm,phong_jitter_error_mm,rasterise_s,network_s,readout_s\n",
        );
        for f in &e.frames {
            let j = |v: fn(&clothsr::msr::eval::Jitter) -> f64| {
                f.jitter_mm
                    .map(|j| format!("{:.5}", v(&j)))
                    .unwrap_or_default()
            };
            let _ = writeln!(
                text,
                "{},{:.5},{:.5},{:.5},{:.5},{:.3},{:.3},{:.4},{:.4},{},{},{},{},{},{:.4},{:.4},{:.4}",
                f.frame,
                f.sr_mm,
                f.sr_max_mm,
                f.upsampled_mm,
                f.phong_mm,
                f.sr_normal_deg,
                f.phong_normal_deg,
                f.sr_bend_w1_deg,
                f.upsampled_bend_w1_deg,
                j(|j| j.sr),
                j(|j| j.phong),
                j(|j| j.gt),
                j(|j| j.sr_err),
                j(|j| j.phong_err),
                f.times.rasterise_s,
                f.times.network_s,
                f.times.readout_s
            );
        }
        clothsr::io::write_atomic(csv, text.as_bytes())?;
    }
    let (sr, up) = (e.mean_sr_mm(), e.mean_upsampled_mm());
    let (t, share) = e.mean_times();
    println!("frames                   {}", e.frames.len());
    println!("fine vertices            {}", seq.fine_mesh.num_vertices());
    println!("mean error, upsampled    {up:.4} mm");
    println!(
        "mean error, Phong        {:.4} mm  ({:.2}× upsampled; the ISR's coarse map, α = {})",
        e.mean_phong_mm(),
        e.mean_phong_mm() / up,
        isr.cfg.phong_alpha
    );
    println!(
        "mean error, SR           {sr:.4} mm  ({:.2}× upsampled)",
        sr / up
    );
    let (sr_deg, phong_deg) = e.mean_normal_deg();
    println!("normal angle error       SR {sr_deg:.2}°, Phong {phong_deg:.2}°");
    let (sr_bend, up_bend) = e.mean_bend_w1_deg();
    println!(
        "bend angles (W1 to gt)   SR {sr_bend:.3}°, upsampled {up_bend:.3}° (the folds' distribution)"
    );
    if let Some(j) = e.mean_jitter_mm() {
        println!(
            "jitter                   SR {:.4} mm, Phong {:.4} mm, fine simulation {:.4} mm",
            j.sr, j.phong, j.gt
        );
        println!(
            "jitter against the fine  SR {:.4} mm, Phong {:.4} mm (mean ‖a − a_fine‖, a the second difference)",
            j.sr_err, j.phong_err
        );
    }
    println!(
        "time per frame           {:.3} s ({:.0} % in the network)",
        t,
        share * 100.0
    );
    Ok(())
}
