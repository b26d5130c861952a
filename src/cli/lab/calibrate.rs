//! `clothsr lab calibrate --data DIR... -o MODELS/coarse.json`: the coarse model chosen on a
//! scene's own data sets (see [`clothsr::pipeline::calibrate`]).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::Context;
use clothsr::corrector::rollout::jitter_directions;
use clothsr::data::read_manifest;
use clothsr::pipeline::calibrate::{best, score, CalibrationSet, Grid, Scored};
use clothsr::pipeline::CoarseCalibration;
use indicatif::{ProgressBar, ProgressStyle};

/// Arguments of `calibrate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Data set directory (`clothsr lab dataset`) of the scene to calibrate for; repeat it for
    /// several drops (the candidates are ranked on all their frames pooled). Measure the choice
    /// on a drop not given here.
    #[arg(value_parser = crate::cli::values::input_dir, long, required = true)]
    data: Vec<PathBuf>,
    /// Where to write the chosen calibration: a models folder's `coarse.json`, read by
    /// `clothsr run --models` when no corrector runs. Written only when every run is done.
    #[arg(value_parser = crate::cli::values::output_file, short, long)]
    output: PathBuf,
    /// Frames to run of every data set (default: all each has after its first).
    #[arg(long)]
    frames: Option<usize>,
    // The lists' defaults are `Grid::default()`'s (a test checks).
    /// Membrane compression factors to try, in (0, 1] (1: the simulator's).
    #[arg(value_parser = crate::cli::values::positive(1.0), long, value_delimiter = ',', default_value = "1,0.1,0.03,0.01")]
    compression: Vec<f64>,
    /// Compression knees to try with each factor below 1, shortenings (0: none).
    #[arg(value_parser = crate::cli::values::non_negative(1.0), long, value_delimiter = ',', default_value = "0")]
    compression_knee: Vec<f64>,
    /// Coulomb friction coefficients against bodies to try; `scene` is the scene's own.
    #[arg(value_parser = friction, long, value_delimiter = ',', default_value = "scene,1,2.5")]
    friction: Vec<Friction>,
    /// Wrinkle bending gains to try (0: off).
    #[arg(value_parser = crate::cli::values::non_negative(crate::cli::values::MAX_FACTOR), long, value_delimiter = ',', default_value = "0,1")]
    wrinkle_bending: Vec<f64>,
    /// Bending stiffness factors to try (1: the fabric's).
    #[arg(value_parser = crate::cli::values::positive(crate::cli::values::MAX_FACTOR), long, value_delimiter = ',', default_value = "1")]
    bending: Vec<f64>,
    /// Crease contacts to try: `on` (the simulator's) and or `off` (coarse edges may cut the
    /// colliders' sharp edges, as M_int's do).
    #[arg(long, value_delimiter = ',', default_value = "on", value_parser = crate::cli::values::on_off())]
    crease_contacts: Vec<bool>,
    /// Run every data set this many more times per candidate, each from its start moved
    /// rigidly by `--jitter-mm` along another horizontal direction, and rank on all runs: where
    /// contact and folds make the coarse path chaotic, one start is one draw.
    #[arg(long, default_value_t = 0)]
    jitter: usize,
    /// How far `--jitter` moves each start, mm.
    #[arg(value_parser = crate::cli::values::positive(crate::cli::values::MAX_MM), long, default_value_t = 0.1)]
    jitter_mm: f64,
    /// Write every candidate's errors as CSV here.
    #[arg(value_parser = crate::cli::values::output_file, long)]
    csv: Option<PathBuf>,
}

/// A `--friction` value: `scene` (the scene's own) or a checked coefficient.
fn friction(v: &str) -> Result<Friction, String> {
    match v.trim() {
        "scene" => Ok(Friction(None)),
        t => {
            let mu: f64 = t
                .parse()
                .map_err(|_| format!("'{t}': not a number (or 'scene' for the scene's own)"))?;
            clothsr::sim::coarse::check_friction(mu).map_err(|e| format!("'{t}': {e}"))?;
            if mu > 100.0 {
                return Err(format!("'{t}': a friction coefficient is at most 100"));
            }
            Ok(Friction(Some(mu)))
        }
    }
}

/// A friction coefficient to try (`None`: the scene's own).
#[derive(Debug, Clone, Copy)]
struct Friction(Option<f64>);

/// A candidate's settings as table cells: compression, knee, friction, gain, bending, creases.
fn cells(c: &CoarseCalibration) -> [String; 6] {
    let or = |v: Option<f64>, none: &str| v.map_or(none.to_string(), |v| v.to_string());
    [
        or(c.compression, "1"),
        or(c.compression_knee, "0"),
        or(c.friction, "scene"),
        or(c.wrinkle_bending, "0"),
        or(c.bending, "1"),
        clothsr::pipeline::crease_label(c.crease_contacts).to_string(),
    ]
}

/// Checks each list of the grid on its own, as a calibration of that one setting would be
/// checked, naming its option.
fn check_lists(args: &Args) -> anyhow::Result<()> {
    type Set = fn(&mut CoarseCalibration, f64);
    let lists: [(&str, &[f64], Set); 4] = [
        ("--compression", &args.compression, |c, v| {
            c.compression = Some(v)
        }),
        ("--compression-knee", &args.compression_knee, |c, v| {
            c.compression_knee = Some(v)
        }),
        ("--wrinkle-bending", &args.wrinkle_bending, |c, v| {
            c.wrinkle_bending = Some(v)
        }),
        ("--bending", &args.bending, |c, v| c.bending = Some(v)),
    ];
    for (option, values, set) in lists {
        for &v in values {
            let mut cal = CoarseCalibration::default();
            set(&mut cal, v);
            cal.check()
                .map_err(|e| anyhow::anyhow!("{option} {v}: {e}"))?;
        }
    }
    anyhow::ensure!(args.frames != Some(0), "--frames must be at least 1");
    Ok(())
}

/// Writes `text` to `path` atomically, creating its folder.
fn write(path: &Path, text: &str) -> anyhow::Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    clothsr::io::write_atomic(path, text.as_bytes())?;
    Ok(())
}

/// `x` as a ratio to the simulator's own model's error, or "n/a" where that failed.
fn ratio(x: f64, own: f64) -> String {
    if own.is_finite() && own > 0.0 {
        format!("{:.2}×", x / own)
    } else {
        "n/a".to_string()
    }
}

/// Runs `calibrate`.
pub fn run(args: Args) -> anyhow::Result<()> {
    check_lists(&args)?;
    let grid = Grid {
        compression: args.compression.clone(),
        compression_knee: args.compression_knee.clone(),
        friction: args.friction.iter().map(|f| f.0).collect(),
        wrinkle_bending: args.wrinkle_bending.clone(),
        bending: args.bending.clone(),
        crease_contacts: args.crease_contacts.clone(),
    };
    let candidates = grid
        .candidates()
        .map_err(|e| anyhow::anyhow!("the grid to search: {e}"))?;
    // Every data set is loaded and checked before the first run.
    let sets = args
        .data
        .iter()
        .map(|dir| {
            let m = read_manifest(dir)?;
            let source = m.source.as_ref().with_context(|| {
                format!(
                    "{}: the data set does not record its scene files",
                    dir.join("manifest.json").display()
                )
            })?;
            Ok(CalibrationSet::load(source.load()?, dir, args.frames)?)
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let shifts: Vec<_> = match args.jitter {
        0 => Vec::new(),
        n => {
            let g = sets[0].gravity_m_s2;
            let d = jitter_directions(g, n);
            anyhow::ensure!(
                d.len() == n,
                "--jitter: the scene has no gravity to jitter across"
            );
            d.into_iter().map(|d| d * (args.jitter_mm * 1e-3)).collect()
        }
    };
    let runs = candidates.len() * sets.len() * (1 + shifts.len());
    tracing::info!(
        "{} candidates × {} data sets × {} starts = {runs} coarse runs",
        candidates.len(),
        sets.len(),
        1 + shifts.len()
    );
    let bar = ProgressBar::new(runs as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} runs {per_sec} eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    // The bar is hidden where stderr is no terminal (a batch log): every tenth there.
    let (every, done) = (runs.div_ceil(10), AtomicUsize::new(0));
    let scored = score(&sets, &candidates, &shifts, || {
        bar.inc(1);
        let n = done.fetch_add(1, Ordering::Relaxed) + 1;
        if bar.is_hidden() && n.is_multiple_of(every) {
            tracing::info!("{n}/{runs} runs");
        }
    })?;
    bar.finish_and_clear();
    let own = scored[0].pooled_mm;
    if !own.is_finite() {
        tracing::warn!("the simulator's own model failed on a run: no ratios to it");
    }
    let table = report(&args, &scored);
    let i = best(&scored).context("the simulator failed on every candidate")?;
    let chosen = scored[i].calibration;
    write(
        &args.output,
        &(serde_json::to_string_pretty(&chosen)? + "\n"),
    )?;
    if let Some(path) = &args.csv {
        write(path, &table)?;
    }
    println!(
        "chosen: {chosen}: {:.3} mm, {} the simulator's own model ({:.3} mm); written to {}",
        scored[i].pooled_mm,
        ratio(scored[i].pooled_mm, own),
        own,
        args.output.display()
    );
    Ok(())
}

/// Prints the candidates best first; returns them as CSV.
fn report(args: &Args, scored: &[Scored]) -> String {
    let own = scored[0].pooled_mm;
    // Each data set's column is named by its folder, and by its whole path where two
    // folders share a name.
    let short = |d: &PathBuf| {
        d.file_name()
            .map_or(d.display().to_string(), |n| n.to_string_lossy().to_string())
    };
    let names: Vec<String> = args
        .data
        .iter()
        .map(|d| {
            let shared = args.data.iter().filter(|e| short(e) == short(d)).count() > 1;
            if shared {
                d.display().to_string()
            } else {
                short(d)
            }
        })
        .collect();
    let mut order: Vec<usize> = (0..scored.len()).collect();
    order.sort_by(|&a, &b| scored[a].pooled_mm.total_cmp(&scored[b].pooled_mm));
    println!(
        "{:>11} {:>6} {:>8} {:>5} {:>7} {:>7} {:>9} {:>7}  per data set, mm",
        "compression", "knee", "friction", "gain", "bending", "creases", "pooled mm", "/ own"
    );
    let mut csv = format!(
        "compression,compression_knee,friction,wrinkle_bending,bending,crease_contacts,pooled_mm,ratio_to_own,{}\n",
        names
            .iter()
            .map(|n| format!("{}_mm", n.replace([',', '\n'], "_")))
            .collect::<Vec<_>>()
            .join(",")
    );
    for &i in &order {
        let s = &scored[i];
        let [c, k, f, g, b, e] = cells(&s.calibration);
        let sets = s.set_means_mm();
        let what = match &s.failed {
            Some(why) => format!("failed: {why}"),
            None => sets
                .iter()
                .map(|m| format!("{m:.3}"))
                .collect::<Vec<_>>()
                .join(" "),
        };
        println!(
            "{c:>11} {k:>6} {f:>8} {g:>5} {b:>7} {e:>7} {:>9.3} {:>7}  {what}",
            s.pooled_mm,
            ratio(s.pooled_mm, own)
        );
        let r = if own.is_finite() {
            s.pooled_mm / own
        } else {
            f64::NAN
        };
        let per: Vec<String> = sets.iter().map(f64::to_string).collect();
        csv += &format!(
            "{c},{k},{f},{g},{b},{e},{},{r},{}\n",
            s.pooled_mm,
            per.join(",")
        );
    }
    csv
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    #[test]
    fn the_default_lists_are_the_library_grid() {
        let cli =
            Cli::try_parse_from(["calibrate", "--data", ".", "-o", "c.json"]).expect("parses");
        let a = cli.args;
        let grid = Grid {
            compression: a.compression.clone(),
            compression_knee: a.compression_knee.clone(),
            friction: a.friction.iter().map(|f| f.0).collect(),
            wrinkle_bending: a.wrinkle_bending.clone(),
            bending: a.bending.clone(),
            crease_contacts: a.crease_contacts.clone(),
        };
        assert_eq!(grid, Grid::default());
        let cli = Cli::try_parse_from([
            "calibrate",
            "--data",
            ".",
            "-o",
            "c.json",
            "--friction",
            "0.2,scene",
        ])
        .expect("parses");
        let given: Vec<Option<f64>> = cli.args.friction.iter().map(|f| f.0).collect();
        assert_eq!(given, vec![Some(0.2), None]);
        assert!(friction("-1").is_err());
        let creases = |v: &str| {
            Cli::try_parse_from([
                "calibrate",
                "--data",
                ".",
                "-o",
                "c.json",
                "--crease-contacts",
                v,
            ])
            .map(|c| c.args.crease_contacts)
        };
        assert_eq!(creases("on,off").expect("parses"), vec![true, false]);
        assert!(creases("maybe").is_err());
    }
}
