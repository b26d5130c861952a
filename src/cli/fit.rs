//! `clothsr fit SHOT -o MODELS [--quality preview|final]`: the best models for one garment and
//! shot ([`clothsr::pipeline::fit`]).

use std::path::PathBuf;
use std::time::Instant;

use clothsr::pipeline::fit::{self, FitOptions, Plan, Quality};
use indicatif::{ProgressBar, ProgressStyle};

/// Arguments of `fit`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The shot: USD, GarmentCode JSON or OBJ cloth.
    shot: PathBuf,
    /// Models folder to make (created; a fit stopped there resumes).
    #[arg(value_parser = crate::cli::values::output_dir, short, long)]
    output: PathBuf,
    #[command(flatten)]
    inputs: super::SceneInputs,
    /// preview (two training variations, 30 frames) or final (five, 90 frames).
    #[arg(long, default_value = "preview")]
    quality: Quality,
    /// Coarse edge length, millimetres.
    #[arg(value_parser = crate::cli::values::positive(crate::cli::values::MAX_MM), long, default_value_t = crate::cli::COARSE_MM)]
    coarse_mm: f64,
    /// Fine edge length, millimetres (the ISR network's pixel).
    #[arg(value_parser = crate::cli::values::positive(crate::cli::values::MAX_MM), long, default_value_t = 2.5)]
    fine_mm: f64,
    /// Frames of each variation (default: the quality's).
    #[arg(long)]
    frames: Option<usize>,
    /// ISR optimiser steps (default: the quality's).
    #[arg(long)]
    isr_steps: Option<usize>,
    /// Train the ISR network from scratch instead of fine-tuning the generic one.
    #[arg(long)]
    from_scratch: bool,
}

/// Runs `fit`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let scene = args.inputs.load(&args.shot)?;
    let shot = args.inputs.source(&args.shot).absolute();
    let generic_isr = if args.from_scratch {
        None
    } else {
        clothsr::pipeline::models::find_generic_models()
            .ok()
            .map(|d| d.join("isr"))
    };
    let opts = FitOptions {
        quality: args.quality,
        coarse_edge_m: args.coarse_mm * 1e-3,
        fine_edge_m: args.fine_mm * 1e-3,
        frames: args.frames,
        isr_steps: args.isr_steps,
        generic_isr,
    };
    let plan = Plan::new(shot, &scene, &opts)?;
    tracing::info!(
        "plan: {} variations, {} tasks, ISR {}; {}",
        plan.variations.len(),
        plan.tasks.len(),
        match &plan.fine_tune_from {
            Some(d) => format!("fine-tuned from {}", d.display()),
            None => "from scratch".into(),
        },
        args.output.join(fit::PLAN_FILE).display()
    );
    let bar = ProgressBar::new(plan.tasks.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:20} {pos}/{len} tasks {elapsed} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let t0 = Instant::now();
    let mut last_log = Instant::now();
    fit::run(&plan, &args.output, |p| {
        bar.set_position(p.done as u64);
        bar.set_message(p.message.clone());
        if bar.is_hidden() && (last_log.elapsed().as_secs() >= 10 || p.message.ends_with("started"))
        {
            tracing::info!("{}/{} tasks: {}", p.done, p.total, p.message);
            last_log = Instant::now();
        }
        std::ops::ControlFlow::Continue(())
    })?;
    bar.finish_and_clear();
    println!(
        "{}: models made in {:.0} s; held-out figures in {}",
        args.output.display(),
        t0.elapsed().as_secs_f64(),
        args.output.join("report.md").display()
    );
    Ok(())
}
