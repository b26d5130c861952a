//! `clothsr eval --gt FINE.usdc --pred OUT.usdc [--baseline B.usdc]…`: per-frame errors of a
//! prediction (and baselines) against a fine simulation, a summary table, a CSV, an
//! error-over-time plot and a Rerun heat map (see [`clothsr::eval`]); where the prediction's file
//! holds the scene's colliders, how many vertices of each series lie inside them.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clothsr::eval::{
    crossings, floor_bound, health, plot, summarise, vertex_errors, write_csv, Animation, Bodies,
    FloorBound, FrameMetrics, Series,
};
use clothsr::viz::{colours, Recorder};

/// Arguments of `eval`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The ground truth: a fine simulation as USD (`clothsr simulate --edge-mm 2.5`), or a
    /// `clothsr lab dataset` directory (its fine frames, matched to the prediction's frames 1..).
    /// Without it, the prediction alone is checked: points that are not finite, cloth inside
    /// the bodies, the largest move of a vertex in one frame.
    #[arg(value_parser = crate::cli::values::input, long)]
    gt: Option<PathBuf>,
    /// The prediction: `clothsr run`'s output.
    #[arg(value_parser = crate::cli::values::input_file, long)]
    pred: PathBuf,
    /// Baselines on the same fine mesh (e.g. `clothsr lab run --upsampled-out`, or a run without
    /// the corrector); NAME=FILE sets the label, else the file's name. A `clothsr lab dataset`
    /// directory is read as its fine frames, like `--gt`: with a `clothsr lab fork` of the ground
    /// truth's data set (its garment moved a fraction of a millimetre), this baseline is the
    /// scene's predictability floor, which no prediction can be expected to beat (its frames
    /// up to the fork count as zero). Every baseline is measured over the prediction's frames.
    #[arg(long, value_name = "[NAME=]FILE", value_parser = baseline)]
    baseline: Vec<(String, PathBuf)>,
    /// The ground truth's twin: a `clothsr lab fork` of its data set (or another fine simulation
    /// whose start differs by a fraction of a millimetre). Adds the two ground truths' distance
    /// (the scene's predictability floor) as the series `floor`, the prediction's error against
    /// the twin, and the least error any prediction from their shared start can average over
    /// the two: half the floor (the triangle inequality), also as a share of each baseline.
    #[arg(value_parser = crate::cli::values::input, long)]
    floor: Option<PathBuf>,
    /// Per-frame metrics of every series as CSV.
    #[arg(value_parser = crate::cli::values::output_file, long)]
    csv: Option<PathBuf>,
    /// Error over time as a PNG plot (the paper's Fig. 11).
    #[arg(value_parser = crate::cli::values::output_file, long)]
    plot: Option<PathBuf>,
    /// A Rerun recording: the ground truth and each series coloured by per-vertex error.
    #[arg(value_parser = crate::cli::values::output_file, long)]
    rrd: Option<PathBuf>,
    /// Error at which the heat map turns red, mm (default: twice the prediction's mean).
    #[arg(value_parser = crate::cli::values::positive(crate::cli::values::MAX_MM), long)]
    heat_max_mm: Option<f64>,
}

/// `NAME=FILE` or `FILE` (labelled by its name), the file existing.
fn baseline(s: &str) -> Result<(String, PathBuf), String> {
    let (name, path) = match s.split_once('=') {
        Some((name, path)) if !name.is_empty() && !name.contains('/') => {
            (Some(name.to_string()), path)
        }
        _ => (None, s),
    };
    let p = crate::cli::values::input(path)?;
    let name = name.unwrap_or_else(|| {
        p.file_stem()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| s.to_string())
    });
    Ok((name, p))
}

/// Runs `eval`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let Some(gt_path) = &args.gt else {
        return check(&args);
    };
    let pred_anim = Animation::read_usd(&args.pred)?;
    // A data set's frames 1.. follow the prediction's first time code.
    let start = pred_anim.time_codes.first().copied().unwrap_or(0.0);
    let gt = Animation::read(gt_path, start)?;
    let inputs = inputs(&args)?;
    let (series, anims) = measure(&gt, pred_anim, &inputs, start)?;
    let pred_mean = print_errors(&series);
    // Cloth inside the bodies: the prediction's file carries the scene's colliders.
    let bodies = Bodies::read_usd(&args.pred)?;
    if !bodies.is_empty() {
        print_inside(&bodies, &gt, &inputs, &anims, &series[0].1);
    }
    print_crossings(&gt, &inputs, &anims, &series[0].1);
    if let Some(twin_path) = &args.floor {
        let twin = anims.last().context("the twin was read")?;
        let b = floor_bound(&gt, twin, twin_path, &anims[0], &args.pred)?;
        print_floor(&b, &series);
    }
    if let Some(path) = &args.csv {
        write_csv(path, &series)?;
        tracing::info!("wrote {}", path.display());
    }
    if let Some(path) = &args.plot {
        let title = format!("{} against {}", args.pred.display(), gt_path.display());
        plot(path, &series, &title)?;
        tracing::info!("wrote {}", path.display());
    }
    if let Some(path) = &args.rrd {
        let max_m = args.heat_max_mm.unwrap_or(2.0 * pred_mean).max(1e-3) * 1e-3;
        write_rrd(path, &gt, &series, &anims, max_m)?;
    }
    Ok(())
}

/// `eval --pred OUT` without a ground truth: the output's [`Health`], and an error (bad input)
/// when a point is not finite.
fn check(args: &Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.baseline.is_empty()
            && args.floor.is_none()
            && args.plot.is_none()
            && args.rrd.is_none()
            && args.csv.is_none(),
        "--baseline, --floor, --csv, --plot and --rrd measure against a ground truth: give --gt"
    );
    let anim = Animation::read_usd(&args.pred)?;
    let bodies = Bodies::read_usd(&args.pred)?;
    let h = health(&anim, &bodies);
    println!("frames: {}", h.frames);
    println!("points not finite: {}", h.non_finite);
    if bodies.is_empty() {
        println!("inside the bodies: no bodies in the file");
    } else {
        println!(
            "inside the bodies: {} frames with any, {:.1} vertices a frame ({:.1} where a body \
             overlaps itself), deepest {:.2} mm",
            h.frames_inside,
            h.inside as f64 / h.frames.max(1) as f64,
            h.in_overlap as f64 / h.frames.max(1) as f64,
            h.deepest_m * 1e3
        );
    }
    println!(
        "cloth through cloth: {:.1} edge-triangle crossings a frame ({:.1} between garments), \
         {} frames with any, at most {} in one",
        h.crossings as f64 / h.frames.max(1) as f64,
        h.crossings_between as f64 / h.frames.max(1) as f64,
        h.frames_crossing,
        h.max_crossings
    );
    println!(
        "largest move of a vertex in one frame: {:.2} mm (at time code {})",
        h.max_move_m * 1e3,
        h.max_move_time
    );
    if h.non_finite > 0 {
        return Err(clothsr::Error::bad_input(
            &args.pred,
            format!("{} point coordinates are not finite", h.non_finite),
        )
        .into());
    }
    Ok(())
}

/// The series to measure, labelled: the prediction, the baselines, then the twin as `floor`.
fn inputs(args: &Args) -> anyhow::Result<Vec<(String, PathBuf)>> {
    let mut inputs = vec![("prediction".to_string(), args.pred.clone())];
    inputs.extend(args.baseline.iter().cloned());
    if let Some(twin) = &args.floor {
        anyhow::ensure!(
            inputs.iter().all(|(name, _)| name != "floor"),
            "--floor names the series `floor`: give the baseline of that name another"
        );
        inputs.push(("floor".to_string(), twin.clone()));
    }
    Ok(inputs)
}

/// Each input's per-frame errors against the ground truth, and its animation; the first input
/// is the prediction, already read.
fn measure(
    gt: &Animation,
    pred_anim: Animation,
    inputs: &[(String, PathBuf)],
    start: f64,
) -> anyhow::Result<(Vec<Series>, Vec<Animation>)> {
    let mut anims = vec![pred_anim];
    for (_, path) in &inputs[1..] {
        anims.push(Animation::read(path, start)?);
    }
    let labelled: Vec<(String, &Animation, &Path)> = inputs
        .iter()
        .zip(&anims)
        .map(|((name, path), a)| (name.clone(), a, path.as_path()))
        .collect();
    let series = clothsr::eval::measure(gt, &labelled)?;
    Ok((series, anims))
}

/// Prints each series' summary and the prediction's ratio to each baseline; returns the
/// prediction's mean error, mm.
fn print_errors(series: &[Series]) -> f64 {
    println!(
        "{:<24} {:>6} {:>9} {:>9} {:>9} {:>10} {:>10} {:>10}",
        "series", "frames", "mean mm", "max mm", "std mm", "normal °", "jitter mm", "gt jitter"
    );
    let pred_mean = summarise(&series[0].1).mean_mm;
    for (name, m) in series {
        let s = summarise(m);
        println!(
            "{:<24} {:>6} {:>9.3} {:>9.3} {:>9.3} {:>10.3} {:>10.4} {:>10.4}",
            name,
            s.frames,
            s.mean_mm,
            s.max_mm,
            s.std_mm,
            s.normal_deg,
            s.jitter_mm,
            s.gt_jitter_mm
        );
    }
    for (name, m) in series.iter().skip(1) {
        let b = summarise(m).mean_mm;
        if b > 0.0 {
            println!("prediction / {name}: {:.3}×", pred_mean / b);
        }
    }
    // The folds and wrinkles in kind, wherever they lie: the distribution of bend angles
    // (between the normals of triangles sharing an edge), which a twin of the ground truth
    // reproduces even where its vertices have drifted away.
    println!(
        "{:<24} {:>12} {:>16} {:>18}",
        "bend angles", "W1 to gt °", "mean °", "ground truth's °"
    );
    for (name, m) in series {
        let s = summarise(m);
        println!(
            "{:<24} {:>12.3} {:>16.3} {:>18.3}",
            name, s.bend_w1_deg, s.bend_mean_deg, s.gt_bend_mean_deg
        );
    }
    pred_mean
}

/// A series named, with its frames at the prediction's time codes (time code, index into the
/// series' frames).
type AtFrames<'a> = (&'a str, &'a Animation, Vec<(f64, usize)>);

/// The ground truth and each series at the prediction's frames `times`.
fn at_prediction_frames<'a>(
    gt: &'a Animation,
    inputs: &'a [(String, PathBuf)],
    anims: &'a [Animation],
    times: &[FrameMetrics],
) -> Vec<AtFrames<'a>> {
    std::iter::once(("ground truth", gt))
        .chain(inputs.iter().map(|(n, _)| n.as_str()).zip(anims))
        .map(|(name, a)| {
            let frames = times
                .iter()
                .filter_map(|f| Some((f.time_code, a.frame_at(f.time_code)?)))
                .collect();
            (name, a, frames)
        })
        .collect()
}

/// Prints how many vertices of the ground truth and of each series lie inside the bodies, over
/// the prediction's frames `times`.
fn print_inside(
    bodies: &Bodies,
    gt: &Animation,
    inputs: &[(String, PathBuf)],
    anims: &[Animation],
    times: &[FrameMetrics],
) {
    println!(
        "{:<24} {:>6} {:>16} {:>14} {:>11}",
        "inside the bodies", "frames", "vertices a frame", "frames with any", "deepest mm"
    );
    for (name, a, frames) in at_prediction_frames(gt, inputs, anims, times) {
        let (mut sum, mut any, mut deepest) = (0usize, 0usize, 0.0f64);
        for &(t, k) in &frames {
            let r = bodies.inside(&a.frames[k], t);
            sum += r.inside;
            any += usize::from(r.inside > 0);
            deepest = deepest.max(r.max_depth_m);
        }
        println!(
            "{:<24} {:>6} {:>16.1} {:>14} {:>11.2}",
            name,
            frames.len(),
            sum as f64 / frames.len().max(1) as f64,
            any,
            deepest * 1e3
        );
    }
}

/// Prints how many fine edges pass through the cloth ([`crossings`]) in the ground truth and in
/// each series, over the prediction's frames `times`: whether an output's cloth through cloth
/// is its own or the fine simulation's too. Garments are told apart by the prediction's meshes
/// (a data set's fine frames are one mesh; every series has the ground truth's triangles).
fn print_crossings(
    gt: &Animation,
    inputs: &[(String, PathBuf)],
    anims: &[Animation],
    times: &[FrameMetrics],
) {
    let Some(pred) = anims.first() else {
        return;
    };
    println!(
        "{:<24} {:>6} {:>16} {:>16} {:>14}",
        "cloth through cloth", "frames", "edges a frame", "between garments", "most a frame"
    );
    for (name, a, frames) in at_prediction_frames(gt, inputs, anims, times) {
        let (mut sum, mut between, mut most) = (0usize, 0usize, 0usize);
        for &(_, k) in &frames {
            let (c, b) = crossings(pred, &a.frames[k]);
            sum += c;
            between += b;
            most = most.max(c);
        }
        let per = |v: usize| v as f64 / frames.len().max(1) as f64;
        println!(
            "{:<24} {:>6} {:>16.1} {:>16.1} {:>14}",
            name,
            frames.len(),
            per(sum),
            per(between),
            most
        );
    }
}

/// Prints the predictability floor `b` and the least error against each baseline.
fn print_floor(b: &FloorBound, series: &[Series]) {
    println!(
        "the two ground truths apart: {:.3} mm over {} frames",
        b.floor_mm, b.frames
    );
    println!(
        "prediction against the twin: {:.3} mm; mean over both: {:.3} mm",
        b.against_twin_mm,
        b.two_truths_mm()
    );
    println!(
        "least possible over both: {:.3} mm (half the floor: no prediction from the shared \
         start averages less over the two ground truths)",
        b.least_mm()
    );
    if b.least_mm() > 0.0 {
        println!(
            "prediction over both / least: {:.2}×",
            b.two_truths_mm() / b.least_mm()
        );
    }
    for (name, m) in series.iter().skip(1) {
        let base = summarise(m).mean_mm;
        if name != "floor" && base > 0.0 {
            println!("least / {name}: {:.3}×", b.least_mm() / base);
        }
    }
}

/// Writes the Rerun recording: the ground truth, and each series as a heat map of its
/// per-vertex error (red at `max_m`) with its mean error plotted.
fn write_rrd(
    path: &Path,
    gt: &Animation,
    series: &[Series],
    anims: &[Animation],
    max_m: f64,
) -> anyhow::Result<()> {
    let rec = Recorder::save("clothsr_eval", path)?;
    rec.mesh_topology("world/ground_truth", &gt.triangles, colours::FINE)?;
    for (name, _) in series {
        rec.mesh_topology(&format!("world/{name}"), &gt.triangles, colours::FINE)?;
    }
    for (k, &t) in gt.time_codes.iter().enumerate() {
        rec.set_frame(t.round() as i64);
        rec.mesh_positions("world/ground_truth", &gt.triangles, &gt.frames[k])?;
        for ((name, m), a) in series.iter().zip(anims) {
            let Some(j) = a.frame_at(t) else { continue };
            let e = vertex_errors(&gt.frames[k], &a.frames[j]);
            rec.mesh_heat_map(
                &format!("world/{name}"),
                &gt.triangles,
                &a.frames[j],
                &e,
                max_m,
            )?;
            if let Some(fm) = m.iter().find(|x| (x.time_code - t).abs() < 1e-6) {
                rec.scalar(&format!("error_mm/{name}"), fm.mean_mm)?;
            }
        }
    }
    let written = rec.finish().context("finishing the recording")?;
    if let Some(p) = written {
        tracing::info!(
            "wrote {} (heat map: blue 0 → red {:.1} mm)",
            p.display(),
            max_m * 1e3
        );
    }
    Ok(())
}
