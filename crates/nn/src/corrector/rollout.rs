//! Rollout evaluation of the corrector against a data set's M_int ground truth (the paper's
//! Fig. 8, 11 and 13): from the ground-truth M_int at the sequence's first step, three coarse
//! sequences are run side by side for the same number of steps:
//!
//! * **sim alone**: the coarse simulator on its own;
//! * **interleaved** (the method): simulator step → corrector → the next step starts from the
//!   corrected mesh (§3.1.3);
//! * **not interleaved** (Fig. 13's ablation): the simulator runs on its own and the corrector
//!   is applied to each of its steps for output only.
//!
//! Errors are mean vertex distances to M_int at every frame end, mm.

use std::time::Instant;

use super::data::{vectors, Sequence};
use super::inference::Corrector;
use clothsr_geometry::error::{Error, Result};
use clothsr_geometry::metrics::mean_distance_mm;
use clothsr_sim::driver::Simulation;
use clothsr_sim::SimState;
use nalgebra::Vector3;

/// Per-frame errors of the three variants, mm.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RolloutErrors {
    /// Frame number (1-based, in the data set).
    pub frame: Vec<usize>,
    /// Coarse simulation alone.
    pub sim_alone_mm: Vec<f64>,
    /// Simulator and corrector interleaved.
    pub interleaved_mm: Vec<f64>,
    /// Corrector applied to the free-running simulation.
    pub not_interleaved_mm: Vec<f64>,
    /// One-step check at every frame end: mean distance to M_int of M_c, one coarse step
    /// from the previous step's M_int, mm (what the corrector has to remove) …
    pub one_step_uncorrected_mm: Vec<f64>,
    /// … and of the corrected M_c, mm.
    pub one_step_corrected_mm: Vec<f64>,
    /// The frame in which the interleaved run stopped because the corrector diverged
    /// ([`super::inference::MAX_CORRECTION_STD`], [`super::inference::MAX_CORRECTED_SPEED_M_S`]);
    /// the report then ends with the last complete frame.
    pub diverged_at_frame: Option<usize>,
    /// Mean edge strain at every frame end, % ([`super::graph::MeshGraph::vertex_strain`]
    /// averaged over vertices): the ground truth's, the simulation alone's and the
    /// interleaved run's. The data's M_int is shortened by its wrinkles (negative); an
    /// interleaved run far from it has left the states the corrector was trained on.
    pub strain_pct: Vec<[f64; 3]>,
    /// The rigid part of the error at every frame end, mm: |mean over vertices of x − x_gt|,
    /// for the simulation alone and the interleaved run. Near the mean distance, the mesh
    /// has slid or sagged as a whole; far below it, its shape differs.
    pub offset_mm: Vec<[f64; 2]>,
    /// The predictability floor at every frame end, mm ([`sequence_distance_mm`]), when the
    /// caller measured it; empty otherwise.
    pub floor_mm: Vec<f64>,
    /// Mean coarse simulator step, ms (interleaved run).
    pub sim_step_ms: f64,
    /// Mean corrector call, ms.
    pub corrector_ms: f64,
}

/// [`RolloutErrors::pooled`]: rollouts on several data sets.
#[derive(Debug, Clone, PartialEq)]
pub struct PooledErrors {
    /// Frames over all data sets.
    pub frames: usize,
    /// Mean over all frames of the simulation alone's error, mm.
    pub sim_alone_mm: f64,
    /// … and of the interleaved run's, mm.
    pub interleaved_mm: f64,
    /// Each data set's interleaved / sim-alone ratio of its own means.
    pub ratios: Vec<f64>,
}

impl PooledErrors {
    /// The pooled interleaved / sim-alone ratio.
    pub fn ratio(&self) -> f64 {
        self.interleaved_mm / self.sim_alone_mm
    }

    /// The largest per-data-set ratio.
    pub fn worst_ratio(&self) -> f64 {
        self.ratios
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

/// |mean(a − b)|, mm.
fn mean_offset_mm(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    let sum: Vector3<f64> = a.iter().zip(b).map(|(p, q)| p - q).sum();
    1e3 * sum.norm() / a.len().max(1) as f64
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// The mean of each column of `rows`.
fn column_means<const N: usize>(rows: &[[f64; N]]) -> [f64; N] {
    std::array::from_fn(|k| mean(&rows.iter().map(|r| r[k]).collect::<Vec<_>>()))
}

impl RolloutErrors {
    /// Mean over frames of the mean edge strain, %: (ground truth, sim alone, interleaved).
    pub fn strain_means(&self) -> [f64; 3] {
        column_means(&self.strain_pct)
    }

    /// Mean over frames of the rigid part of the error, mm: (sim alone, interleaved).
    pub fn offset_means(&self) -> [f64; 2] {
        column_means(&self.offset_mm)
    }

    /// Mean of the predictability floor over frames, mm (`None` when it was not measured).
    pub fn floor_mean(&self) -> Option<f64> {
        (!self.floor_mm.is_empty()).then(|| mean(&self.floor_mm))
    }

    /// Mean one-step errors over frames: (uncorrected M_c, corrected M_c), mm.
    pub fn one_step_means(&self) -> (f64, f64) {
        (
            mean(&self.one_step_uncorrected_mm),
            mean(&self.one_step_corrected_mm),
        )
    }

    /// Mean over frames of each variant: (sim alone, interleaved, not interleaved), mm.
    pub fn means(&self) -> (f64, f64, f64) {
        (
            mean(&self.sim_alone_mm),
            mean(&self.interleaved_mm),
            mean(&self.not_interleaved_mm),
        )
    }

    /// Several rollouts (one per held-out data set) summed up: one drop's rollout cannot rank
    /// two correctors whose means differ only a little (the trajectories are chaotic), so
    /// figures are pooled over frames of several drops, with each drop's ratio beside them.
    pub fn pooled(runs: &[RolloutErrors]) -> PooledErrors {
        let frames: usize = runs.iter().map(|e| e.sim_alone_mm.len()).sum();
        let total = |f: fn(&RolloutErrors) -> &Vec<f64>| -> f64 {
            runs.iter().flat_map(|e| f(e).iter()).sum::<f64>() / frames.max(1) as f64
        };
        PooledErrors {
            frames,
            sim_alone_mm: total(|e| &e.sim_alone_mm),
            interleaved_mm: total(|e| &e.interleaved_mm),
            ratios: runs
                .iter()
                .map(|e| {
                    let (a, b, _) = e.means();
                    b / a
                })
                .collect(),
        }
    }

    /// Least-squares slope of the interleaved error over frames, mm per 100 frames (the
    /// growth trend).
    pub fn interleaved_trend_mm_per_100(&self) -> f64 {
        let n = self.interleaved_mm.len() as f64;
        if n < 2.0 {
            return 0.0;
        }
        let xs: Vec<f64> = (0..self.interleaved_mm.len()).map(|i| i as f64).collect();
        let (mx, my) = (
            xs.iter().sum::<f64>() / n,
            self.interleaved_mm.iter().sum::<f64>() / n,
        );
        let cov: f64 = xs
            .iter()
            .zip(&self.interleaved_mm)
            .map(|(x, y)| (x - mx) * (y - my))
            .sum();
        let var: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
        100.0 * cov / var
    }

    /// CSV: one row per frame, the columns named after the fields (`floor_mm` last, when
    /// measured).
    pub fn csv(&self) -> String {
        let floor = !self.floor_mm.is_empty();
        let mut s = String::from(
            "frame,sim_alone_mm,interleaved_mm,not_interleaved_mm,one_step_uncorrected_mm,\
             one_step_corrected_mm,strain_gt_pct,strain_sim_alone_pct,strain_interleaved_pct,\
             offset_sim_alone_mm,offset_interleaved_mm",
        );
        s += if floor { ",floor_mm\n" } else { "\n" };
        for i in 0..self.frame.len() {
            let [g, a, b] = self.strain_pct[i];
            let [oa, oi] = self.offset_mm[i];
            let f = if floor {
                format!(",{:.4}", self.floor_mm[i])
            } else {
                String::new()
            };
            s += &format!(
                "{},{:.4},{:.4},{:.4},{:.5},{:.5},{g:.4},{a:.4},{b:.4},{oa:.4},{oi:.4}{f}\n",
                self.frame[i],
                self.sim_alone_mm[i],
                self.interleaved_mm[i],
                self.not_interleaved_mm[i],
                self.one_step_uncorrected_mm[i],
                self.one_step_corrected_mm[i]
            );
        }
        s
    }
}

/// Mean vertex distance, mm, between the M_int of two data sets of the same coarse mesh at
/// the end of each frame in `frames` (both loaded over ranges holding them). With `other` a
/// fine simulation of the same scene from a start moved by a tiny offset, this is the
/// predictability floor: how far the ground truth itself goes from a trajectory that started
/// next to it.
pub fn sequence_distance_mm(
    seq: &Sequence,
    other: &Sequence,
    frames: &[usize],
) -> Result<Vec<f64>> {
    let s = seq.manifest.steps_per_frame;
    if other.manifest.steps_per_frame != s
        || other.manifest.coarse_vertices != seq.manifest.coarse_vertices
    {
        return Err(Error::bad_input(
            &other.dir,
            format!(
                "not comparable with {}: {} coarse vertices and {} steps a frame against {} and {s}",
                seq.dir.display(),
                other.manifest.coarse_vertices,
                other.manifest.steps_per_frame,
                seq.manifest.coarse_vertices
            ),
        ));
    }
    fn end(q: &Sequence, f: usize, s: usize) -> Result<&super::data::Step> {
        f.checked_sub(q.first_frame)
            .map(|k| k * s + s - 1)
            .and_then(|i| q.steps.get(i))
            .ok_or_else(|| Error::bad_input(&q.dir, format!("frame {f} is not loaded")))
    }
    frames
        .iter()
        .map(|&f| {
            Ok(mean_distance_mm(
                &vectors(&end(seq, f, s)?.int_x),
                &vectors(&end(other, f, s)?.int_x),
            ))
        })
        .collect()
}

/// Short-horizon errors: rollouts of a few frames from the ground truth at many starts, their
/// errors averaged per frame after the start (the accuracy within the horizon over which the
/// ground truth itself is predictable; see [`sequence_distance_mm`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HorizonErrors {
    /// The start frames.
    pub starts: Vec<usize>,
    /// Mean over starts of the simulation alone's error k + 1 frames after the start, mm.
    pub sim_alone_mm: Vec<f64>,
    /// The same for the interleaved run.
    pub interleaved_mm: Vec<f64>,
}

impl HorizonErrors {
    /// Averages `runs` (each [`evaluate_from`] one start, `starts` their start frames) frame
    /// by frame over the first `horizon` frames; a run shorter than that (diverged) is an
    /// error naming its start.
    pub fn from_runs(starts: &[usize], runs: &[RolloutErrors], horizon: usize) -> Result<Self> {
        let mut out = HorizonErrors {
            starts: starts.to_vec(),
            sim_alone_mm: vec![0.0; horizon],
            interleaved_mm: vec![0.0; horizon],
        };
        for (start, r) in starts.iter().zip(runs) {
            if r.interleaved_mm.len() < horizon {
                return Err(Error::Simulation(format!(
                    "the interleaved run from frame {start} stopped after {} of {horizon} frames",
                    r.interleaved_mm.len()
                )));
            }
            for k in 0..horizon {
                out.sim_alone_mm[k] += r.sim_alone_mm[k] / runs.len() as f64;
                out.interleaved_mm[k] += r.interleaved_mm[k] / runs.len() as f64;
            }
        }
        Ok(out)
    }

    /// CSV: one row per frame after the start.
    pub fn csv(&self) -> String {
        let mut s = String::from("frames_after_start,sim_alone_mm,interleaved_mm,ratio\n");
        for k in 0..self.sim_alone_mm.len() {
            s += &format!(
                "{},{:.4},{:.4},{:.4}\n",
                k + 1,
                self.sim_alone_mm[k],
                self.interleaved_mm[k],
                self.interleaved_mm[k] / self.sim_alone_mm[k]
            );
        }
        s
    }
}

/// Runs the three variants over `frames` frames of `seq` (from its first stored step) with
/// `sims`, three instances of the data set's coarse simulation
/// ([`clothsr_io::data::coarse_simulation`], whose time at the data set's frame 0 is `t0_s`): one
/// for the simulation alone, one for the interleaved run, one for the one-step check (at each
/// frame end, a coarse step from the ground truth's previous step, so that the check is of
/// this simulator, which may differ from the one that made the data set). They must be
/// separate: a simulator carries state from step to step (its warm start, its adaptive
/// contact margin) and the one-Newton-step solver's result depends on it. `on_frame` sees
/// each frame's errors.
pub fn evaluate(
    seq: &Sequence,
    sims: [&mut Simulation; 3],
    t0_s: f64,
    corrector: &Corrector,
    frames: usize,
    on_frame: impl FnMut(usize, f64, f64, f64),
) -> Result<RolloutErrors> {
    evaluate_from(seq, 0, sims, t0_s, corrector, frames, on_frame)
}

/// [`evaluate`] from the ground truth at the loaded sequence's step `start_step` (a multiple
/// of the steps per frame: the first step of one of its frames) instead of its first.
pub fn evaluate_from(
    seq: &Sequence,
    start_step: usize,
    sims: [&mut Simulation; 3],
    t0_s: f64,
    corrector: &Corrector,
    frames: usize,
    on_frame: impl FnMut(usize, f64, f64, f64),
) -> Result<RolloutErrors> {
    let none = Vector3::zeros();
    evaluate_shifted(
        seq, start_step, none, sims, t0_s, corrector, frames, on_frame,
    )
}

/// `n` unit directions perpendicular to `gravity`, evenly spread over the circle (for a
/// downward gravity: horizontal), the first along the horizontal axis closest to x; `[]` for
/// zero gravity or `n` = 0.
pub fn jitter_directions(gravity: Vector3<f64>, n: usize) -> Vec<Vector3<f64>> {
    let Some(down) = gravity.try_normalize(1e-12) else {
        return Vec::new();
    };
    let axis = [Vector3::x(), Vector3::z(), Vector3::y()]
        .into_iter()
        .min_by(|a, b| a.dot(&down).abs().total_cmp(&b.dot(&down).abs()))
        .unwrap_or_else(Vector3::x);
    let a = (axis - down * axis.dot(&down)).normalize();
    let b = down.cross(&a);
    (0..n)
        .map(|k| {
            let t = std::f64::consts::TAU * k as f64 / n as f64;
            a * t.cos() + b * t.sin()
        })
        .collect()
}

/// [`evaluate_from`] with the start of the simulation alone and of the interleaved run moved
/// rigidly by `shift`, m, while the ground truth stays: a start a fraction of a millimetre
/// away, to measure how much of a rollout's error is a draw of a chaotic scene (contact,
/// folds and friction decide between fold layouts on such differences; `clothsr lab rollout
/// --jitter`). The one-step check starts from the ground truth as ever.
#[allow(clippy::too_many_arguments)]
pub fn evaluate_shifted(
    seq: &Sequence,
    start_step: usize,
    shift: Vector3<f64>,
    sims: [&mut Simulation; 3],
    t0_s: f64,
    corrector: &Corrector,
    frames: usize,
    mut on_frame: impl FnMut(usize, f64, f64, f64),
) -> Result<RolloutErrors> {
    let s = seq.manifest.steps_per_frame;
    let h = seq.manifest.dt_s;
    let steps = frames * s;
    if !start_step.is_multiple_of(s) || start_step + steps + 1 > seq.steps.len() {
        return Err(Error::bad_input(
            &seq.dir,
            format!(
                "{frames} frames from step {start_step} asked for, the loaded sequence has {} \
                 steps after its first ({s} a frame)",
                seq.steps.len().saturating_sub(1)
            ),
        ));
    }
    let steps_at = |i: usize| &seq.steps[start_step + i];
    let mut start = seq.int_state(start_step, t0_s);
    start.x.iter_mut().for_each(|x| *x += shift);
    let (mut alone, mut inter) = (start.clone(), start);
    let mut out = RolloutErrors::default();
    let (mut sim_s, mut corr_s) = (0.0, 0.0);
    for i in 1..=steps {
        // The not-interleaved variant corrects the free run at frame ends only.
        let frame_end = (i + 1) % s == 0;
        let alone_start_v = if frame_end {
            alone.v.clone()
        } else {
            Vec::new()
        };
        alone = sims[0].step_from(&alone)?.0;
        let t = Instant::now();
        let mut c = sims[1].step_from(&inter)?.0;
        sim_s += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let corrected = corrector.correct(&inter.v, &mut c, sims[1]);
        corr_s += t.elapsed().as_secs_f64();
        if let Err(e) = corrected {
            let frame = seq.first_frame + (start_step + i + 1).div_ceil(s) - 1;
            tracing::warn!("interleaved rollout stopped in frame {frame}: {e}");
            out.diverged_at_frame = Some(frame);
            break;
        }
        inter = c;
        // The data set's frame ends are its steps s, 2s, …; step 0 here is its step 1.
        if frame_end {
            let gt = vectors(&steps_at(i).int_x);
            let mut fixed = alone.clone();
            corrector.correct(&alone_start_v, &mut fixed, sims[0])?;
            let e = (
                mean_distance_mm(&alone.x, &gt),
                mean_distance_mm(&inter.x, &gt),
                mean_distance_mm(&fixed.x, &gt),
            );
            let before = steps_at(i - 1);
            let mut data_c = sims[2]
                .step_from(&SimState {
                    x: vectors(&before.int_x),
                    v: vectors(&before.int_v),
                    t_s: inter.t_s - h,
                })?
                .0;
            out.one_step_uncorrected_mm
                .push(mean_distance_mm(&data_c.x, &gt));
            corrector.correct(&vectors(&before.int_v), &mut data_c, sims[2])?;
            out.one_step_corrected_mm
                .push(mean_distance_mm(&data_c.x, &gt));
            let strain = |x: &[Vector3<f64>]| {
                let e = seq.graph.vertex_strain(x);
                100.0 * e.iter().sum::<f64>() / e.len().max(1) as f64
            };
            out.strain_pct
                .push([strain(&gt), strain(&alone.x), strain(&inter.x)]);
            out.offset_mm
                .push([mean_offset_mm(&alone.x, &gt), mean_offset_mm(&inter.x, &gt)]);
            let frame = seq.first_frame + (start_step + i) / s;
            out.frame.push(frame);
            out.sim_alone_mm.push(e.0);
            out.interleaved_mm.push(e.1);
            out.not_interleaved_mm.push(e.2);
            on_frame(frame, e.0, e.1, e.2);
        }
    }
    let done = (out.frame.len() * s).max(1) as f64;
    out.sim_step_ms = 1e3 * sim_s / done;
    out.corrector_ms = 1e3 * corr_s / done;
    Ok(out)
}

/// The interleaved run alone (simulator step → corrector → the next step from the corrected
/// mesh, §3.1.3) over `frames` frames of `seq` from its first step with `sim` (the data set's
/// coarse simulation, fresh, whose time at the data set's frame 0 is `t0_s`): the mean
/// distance to M_int at each frame end, mm, or `None` where the corrector diverged. What
/// training validates its network on ([`super::training::ValidationSet`]).
pub fn interleaved_errors(
    seq: &Sequence,
    sim: &mut Simulation,
    t0_s: f64,
    corrector: &Corrector,
    frames: usize,
) -> Result<Option<Vec<f64>>> {
    check_frames(seq, frames)?;
    let s = seq.manifest.steps_per_frame;
    let mut errors = Vec::with_capacity(frames);
    let done = interleaved_run(seq, sim, t0_s, corrector, frames * s, |i, state| {
        if (i + 1).is_multiple_of(s) {
            errors.push(mean_distance_mm(&state.x, &vectors(&seq.steps[i].int_x)));
        }
    })?;
    Ok(done.then_some(errors))
}

/// Fails unless `seq` holds `frames` frames of steps after its first step.
pub fn check_frames(seq: &Sequence, frames: usize) -> Result<()> {
    let s = seq.manifest.steps_per_frame;
    if frames * s + 1 > seq.steps.len() {
        return Err(Error::bad_input(
            &seq.dir,
            format!(
                "{frames} frames asked for, the loaded sequence has {} steps after its first \
                 ({s} a frame)",
                seq.steps.len().saturating_sub(1)
            ),
        ));
    }
    Ok(())
}

/// Runs the interleaved simulation (as [`interleaved_errors`]) for at most `steps` steps of
/// `seq` from its first step's M_int, stopping at the sequence's last step, and hands `visit`
/// each corrected state with the index of the sequence step it stands for (1, 2, …). False
/// where the corrector diverged first, or drove the simulator to fail (the states before
/// were visited); true for a sequence without steps.
pub fn interleaved_run(
    seq: &Sequence,
    sim: &mut Simulation,
    t0_s: f64,
    corrector: &Corrector,
    steps: usize,
    mut visit: impl FnMut(usize, &SimState),
) -> Result<bool> {
    if seq.steps.is_empty() {
        return Ok(true);
    }
    let mut state = seq.int_state(0, t0_s);
    for i in 1..=steps.min(seq.steps.len().saturating_sub(1)) {
        let mut c = match sim.step_from(&state) {
            Ok((c, _)) => c,
            // The simulator gave up on a state the corrector made: the corrector's failure.
            Err(Error::Simulation(_)) => return Ok(false),
            Err(e) => return Err(e),
        };
        if corrector.correct(&state.v, &mut c, sim).is_err() {
            return Ok(false);
        }
        state = c;
        visit(i, &state);
    }
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(alone: &[f64], inter: &[f64]) -> RolloutErrors {
        RolloutErrors {
            sim_alone_mm: alone.to_vec(),
            interleaved_mm: inter.to_vec(),
            not_interleaved_mm: alone.to_vec(),
            ..RolloutErrors::default()
        }
    }

    #[test]
    fn pooled_means_weigh_every_frame_and_keep_each_sets_ratio() {
        // 3 frames at 10 → 5 mm and 1 frame at 2 → 4 mm: pooled over 4 frames 8 → 4.75 mm,
        // not the mean of the sets' means (6 → 4.5).
        let p = RolloutErrors::pooled(&[run(&[10.0; 3], &[5.0; 3]), run(&[2.0], &[4.0])]);
        assert_eq!(p.frames, 4);
        assert!((p.sim_alone_mm - 8.0).abs() < 1e-12);
        assert!((p.interleaved_mm - 4.75).abs() < 1e-12);
        assert!((p.ratio() - 4.75 / 8.0).abs() < 1e-12);
        assert_eq!(p.ratios, vec![0.5, 2.0]);
        assert_eq!(p.worst_ratio(), 2.0);
    }
}
