//! Calibrating the coarse model on a scene's own training drops (`clothsr lab calibrate`).
//!
//! Without a corrector the coarse simulation itself has to land near M_int, the downsampled
//! fine simulation (§3.1.2). A 20 mm sheet cannot wrinkle as a 2.5 mm one does, so some of its
//! parameters are better set for the coarse mesh than for the cloth: a membrane that gives under
//! compression as the fine cloth's wrinkles do, the grip on bodies, the bending of a shortened
//! sheet ([`CoarseCalibration`]). Which of them helps is the scene's (the three balls want a
//! strong grip that makes the table worse), so they are chosen on that scene's data sets: each
//! candidate's simulation alone is run from each data set's first M_int and measured against
//! its M_int at every frame end, and the candidate with the lowest mean error over all those
//! frames wins. The simulator's own model is always a candidate, so a calibration that does
//! not beat it is never chosen.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::CoarseCalibration;
use crate::corrector::data::{vectors, Sequence};
use crate::corrector::rollout::check_frames;
use crate::error::{Error, Result};
use crate::metrics::mean_distance_mm;
use crate::scene::Scene;
use crate::sim::driver::Simulation;

/// The values to try for each setting of [`CoarseCalibration`]; their product is searched.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// Membrane compression factors, in (0, 1] (1: the simulator's).
    pub compression: Vec<f64>,
    /// Compression knees, shortenings (0: none); tried only with a factor below 1.
    pub compression_knee: Vec<f64>,
    /// Friction coefficients against bodies (`None`: the scene's).
    pub friction: Vec<Option<f64>>,
    /// Wrinkle bending gains (0: off).
    pub wrinkle_bending: Vec<f64>,
    /// Bending stiffness factors (1: the fabric's).
    pub bending: Vec<f64>,
    /// Crease contacts on or off (true: the simulator's).
    pub crease_contacts: Vec<bool>,
}

impl Default for Grid {
    /// The settings that mattered on the sample scenes
    /// (`docs/experiments/three_balls.md`): 24 candidates.
    fn default() -> Self {
        Grid {
            compression: vec![1.0, 0.1, 0.03, 0.01],
            compression_knee: vec![0.0],
            friction: vec![None, Some(1.0), Some(2.5)],
            wrinkle_bending: vec![0.0, 1.0],
            bending: vec![1.0],
            crease_contacts: vec![true],
        }
    }
}

impl Grid {
    /// Every combination, checked, without repeats, in the grid's order with the simulator's
    /// own model ([`CoarseCalibration::default`]) first whether or not the grid names it.
    /// A knee is combined with factors below 1 only (a stiff membrane has none to restore),
    /// and the defaults are stored as `None` (factors 1, knee 0, gain 0).
    pub fn candidates(&self) -> Result<Vec<CoarseCalibration>> {
        let mut out = vec![CoarseCalibration::default()];
        for &c in &self.compression {
            for &k in &self.compression_knee {
                if c == 1.0 && k != 0.0 {
                    continue;
                }
                for &mu in &self.friction {
                    for &g in &self.wrinkle_bending {
                        for &b in &self.bending {
                            for &e in &self.crease_contacts {
                                let cal = CoarseCalibration {
                                    compression: (c != 1.0).then_some(c),
                                    compression_knee: (k != 0.0).then_some(k),
                                    friction: mu,
                                    wrinkle_bending: (g != 0.0).then_some(g),
                                    bending: (b != 1.0).then_some(b),
                                    crease_contacts: (!e).then_some(false),
                                };
                                cal.check()?;
                                if !out.contains(&cal) {
                                    out.push(cal);
                                }
                            }
                        }
                    }
                }
            }
        }
        Ok(out)
    }
}

/// The coarse simulation alone over `frames` frames of `seq` from its first step's M_int
/// moved rigidly by `shift`, m (`sim`: the data set's coarse simulation, fresh, whose time at
/// the data set's frame 0 is `t0_s`): the mean distance to M_int at each frame end, mm.
/// As the simulation alone of [`crate::corrector::rollout::evaluate_shifted`].
pub fn sim_alone_errors(
    seq: &Sequence,
    sim: &mut Simulation,
    t0_s: f64,
    frames: usize,
    shift: Vector3<f64>,
) -> Result<Vec<f64>> {
    check_frames(seq, frames)?;
    let s = seq.manifest.steps_per_frame;
    let steps = frames * s;
    let mut state = seq.int_state(0, t0_s);
    state.x.iter_mut().for_each(|x| *x += shift);
    let mut errors = Vec::with_capacity(frames);
    for i in 1..=steps {
        state = sim.step_from(&state)?.0;
        // The data set's frame ends are its steps s, 2s, …; step 0 here is its step 1.
        if (i + 1).is_multiple_of(s) {
            errors.push(mean_distance_mm(&state.x, &vectors(&seq.steps[i].int_x)));
        }
    }
    Ok(errors)
}

/// A data set to calibrate on: its scene (as given to `clothsr lab dataset`), its loaded
/// sequence and the frames to run.
pub struct CalibrationSet {
    /// The scene the data set was made from, before its variation.
    pub scene: Scene,
    /// Its coarse sequence, loaded from frame 1 over `frames + 1` frames.
    pub seq: Sequence,
    /// Frames to run from its first step.
    pub frames: usize,
    /// The scene's gravity, m/s².
    pub gravity_m_s2: Vector3<f64>,
}

impl CalibrationSet {
    /// Loads data set `dir` of `scene` for `frames` frames (`None`: all it has after its
    /// first).
    pub fn load(scene: Scene, dir: &std::path::Path, frames: Option<usize>) -> Result<Self> {
        let m = crate::data::read_manifest(dir)?;
        m.check_reference(dir)?;
        let frames = frames.unwrap_or(m.frames_done.saturating_sub(1));
        if frames == 0 || frames + 1 > m.frames_done {
            return Err(Error::bad_input(
                dir.join("manifest.json"),
                format!(
                    "the data set has {} frames: too few to run {frames} from its first",
                    m.frames_done
                ),
            ));
        }
        let sim = crate::data::coarse_simulation(&scene, dir, 1)?;
        let seq = Sequence::load(dir, Some(1..=1 + frames), &sim)?;
        Ok(CalibrationSet {
            scene,
            seq,
            frames,
            gravity_m_s2: sim.sim.params.gravity_m_s2,
        })
    }

    /// A fresh coarse simulation of the data set with `cal` applied, and its time at the data
    /// set's frame 0, s.
    fn simulation(&self, cal: &CoarseCalibration) -> Result<(Simulation, f64)> {
        let mut sim = crate::data::coarse_simulation(&self.scene, &self.seq.dir, 1)?;
        cal.apply(&mut sim)?;
        let t0 = sim.state.t_s;
        Ok((sim, t0))
    }
}

/// One candidate's errors.
#[derive(Debug, Clone, PartialEq)]
pub struct Scored {
    /// The candidate.
    pub calibration: CoarseCalibration,
    /// Per data set, per start (the first unmoved, then each of the shifts), the mean error
    /// over its frames, mm.
    pub run_means_mm: Vec<Vec<f64>>,
    /// The mean over every frame of every run, mm; infinite where a run failed.
    pub pooled_mm: f64,
    /// Why a run failed (the simulator gave up on this coarse model), if one did.
    pub failed: Option<String>,
}

impl Scored {
    /// The mean error of each data set over its runs' frames, mm.
    pub fn set_means_mm(&self) -> Vec<f64> {
        self.run_means_mm
            .iter()
            .map(|r| r.iter().sum::<f64>() / r.len().max(1) as f64)
            .collect()
    }
}

/// Runs every candidate's simulation alone on every set, from its first M_int and from it
/// moved by each of `shifts`, m (a fraction of a millimetre: where contact and folds make the
/// coarse path chaotic, one start is one draw), in parallel; `done` is called after each
/// run. A candidate the simulator fails on is scored infinite with the reason, not an error.
/// Returns the candidates in the given order.
pub fn score(
    sets: &[CalibrationSet],
    candidates: &[CoarseCalibration],
    shifts: &[Vector3<f64>],
    done: impl Fn() + Sync,
) -> Result<Vec<Scored>> {
    let starts: Vec<Vector3<f64>> = std::iter::once(Vector3::zeros())
        .chain(shifts.iter().copied())
        .collect();
    let (n_sets, n_starts) = (sets.len(), starts.len());
    let jobs: Vec<(usize, usize, usize)> = (0..candidates.len())
        .flat_map(|c| (0..n_sets).flat_map(move |s| (0..n_starts).map(move |k| (c, s, k))))
        .collect();
    let runs: Vec<std::result::Result<Vec<f64>, Error>> = jobs
        .par_iter()
        .map(|&(c, s, k)| {
            let set = &sets[s];
            let (mut sim, t0) = set.simulation(&candidates[c])?;
            let e = sim_alone_errors(&set.seq, &mut sim, t0, set.frames, starts[k]);
            done();
            e
        })
        .collect();
    let mut out: Vec<Scored> = candidates
        .iter()
        .map(|&calibration| Scored {
            calibration,
            run_means_mm: vec![Vec::new(); sets.len()],
            pooled_mm: 0.0,
            failed: None,
        })
        .collect();
    let mut sums = vec![(0.0, 0usize); candidates.len()];
    for (&(c, s, _), run) in jobs.iter().zip(runs) {
        match run {
            Ok(e) => {
                let sum: f64 = e.iter().sum();
                out[c].run_means_mm[s].push(sum / e.len().max(1) as f64);
                sums[c].0 += sum;
                sums[c].1 += e.len();
            }
            Err(Error::Simulation(why)) => {
                out[c].failed.get_or_insert(why);
                out[c].run_means_mm[s].push(f64::INFINITY);
            }
            Err(e) => return Err(e),
        }
    }
    for (o, (sum, n)) in out.iter_mut().zip(sums) {
        o.pooled_mm = if o.failed.is_some() || n == 0 {
            f64::INFINITY
        } else {
            sum / n as f64
        };
    }
    Ok(out)
}

/// The index of the best scored candidate: the lowest pooled error, the earlier on a tie
/// (the simulator's own model comes first); `None` when every candidate failed.
pub fn best(scored: &[Scored]) -> Option<usize> {
    scored
        .iter()
        .enumerate()
        .filter(|(_, s)| s.pooled_mm.is_finite())
        .min_by(|a, b| a.1.pooled_mm.total_cmp(&b.1.pooled_mm))
        .map(|(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_starts_with_the_simulators_model_and_skips_knees_of_a_stiff_membrane() {
        let grid = Grid {
            compression: vec![0.03, 1.0],
            compression_knee: vec![0.0, 0.006],
            friction: vec![None, Some(2.5)],
            wrinkle_bending: vec![0.0],
            bending: vec![1.0],
            crease_contacts: vec![true],
        };
        let c = grid.candidates().expect("valid grid");
        // The simulator's own first; then 0.03 × {no knee, knee} × {scene, 2.5}; then 1 ×
        // {scene (already there), 2.5}: 1 + 4 + 1.
        assert_eq!(c.len(), 6);
        assert_eq!(c[0], CoarseCalibration::default());
        assert_eq!(
            c[2],
            CoarseCalibration {
                compression: Some(0.03),
                friction: Some(2.5),
                ..CoarseCalibration::default()
            }
        );
        assert!(c
            .iter()
            .all(|k| k.compression.is_some() || k.compression_knee.is_none()));
        assert_eq!(c.iter().filter(|k| k.compression_knee.is_some()).count(), 2);
        let bad = Grid {
            compression: vec![1.5],
            ..Grid::default()
        };
        let e = bad.candidates().expect_err("factor above 1").to_string();
        assert!(e.contains("compression"), "{e}");
        assert_eq!(Grid::default().candidates().ok().map(|c| c.len()), Some(24));
        // Crease contacts off doubles the grid; on is stored as unset.
        let both = Grid {
            crease_contacts: vec![true, false],
            ..Grid::default()
        };
        let c = both.candidates().expect("valid grid");
        assert_eq!(c.len(), 48);
        assert_eq!(
            c.iter()
                .filter(|k| k.crease_contacts == Some(false))
                .count(),
            24
        );
        assert!(c.iter().all(|k| k.crease_contacts != Some(true)));
    }

    #[test]
    fn the_best_is_the_lowest_finite_and_the_first_on_a_tie() {
        let s = |mm: f64| Scored {
            calibration: CoarseCalibration::default(),
            run_means_mm: vec![vec![mm]],
            pooled_mm: mm,
            failed: mm.is_infinite().then(|| "diverged".to_string()),
        };
        assert_eq!(best(&[s(3.0), s(f64::INFINITY), s(2.0), s(2.0)]), Some(2));
        assert_eq!(best(&[s(2.0), s(2.0)]), Some(0));
        assert_eq!(best(&[s(f64::INFINITY)]), None);
        assert_eq!(best(&[]), None);
        let two = Scored {
            run_means_mm: vec![vec![1.0, 3.0], vec![4.0]],
            ..s(0.0)
        };
        assert_eq!(two.set_means_mm(), vec![2.0, 4.0]);
    }
}
