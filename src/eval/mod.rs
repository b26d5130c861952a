//! Evaluation against a fine simulation (the paper's §4.1): per frame the vertex-wise Euclidean
//! distance (mean, max, std), the mean angle between vertex normals, and temporal jitter
//! (mean ‖x_{t+1} − 2x_t + x_{t−1}‖, set beside the ground truth's own); error-over-time plots
//! (Fig. 11) and per-vertex heat maps (Fig. 9/10) through [`crate::viz`].

pub mod converge;

use std::path::Path;

use nalgebra::Vector3;

use crate::error::{Error, Result};
use crate::io::usd::{read_usd, MeshRole};
pub use crate::metrics::{
    bend_angles_deg, hinges, jitter_m, mean_distance_mm, mean_max_std, normal_angle_deg,
    vertex_errors, wasserstein1_sorted,
};
use crate::sim::collide::PushOut;

/// The cloth of an animation file: every cloth mesh of the stage, concatenated in prim order.
#[derive(Debug, Clone, PartialEq)]
pub struct Animation {
    /// Names of the cloth meshes (prim paths) with their vertex ranges.
    pub parts: Vec<(String, std::ops::Range<usize>)>,
    /// Triangles over the concatenated vertices.
    pub triangles: Vec<[u32; 3]>,
    /// Time code of each frame.
    pub time_codes: Vec<f64>,
    /// Positions per frame, metres.
    pub frames: Vec<Vec<Vector3<f64>>>,
}

impl Animation {
    /// Reads the cloth meshes of a USD file (garments written by `clothsr simulate` or
    /// `clothsr run`). Fails when the file has no animated cloth or its meshes disagree on the
    /// frames they are sampled at.
    pub fn read_usd(path: &Path) -> Result<Animation> {
        let stage = read_usd(path)?;
        let cloth: Vec<_> = stage
            .meshes
            .into_iter()
            .filter(|m| m.role == MeshRole::Cloth)
            .collect();
        if cloth.is_empty() {
            return Err(Error::bad_input(
                path,
                "no cloth mesh (a mesh with clothsr's ClothsrGarmentAPI) in this stage",
            ));
        }
        let time_codes = cloth[0].time_codes.clone();
        let mut anim = Animation {
            parts: Vec::new(),
            triangles: Vec::new(),
            time_codes: time_codes.clone(),
            frames: vec![Vec::new(); time_codes.len().max(1)],
        };
        for m in &cloth {
            if m.time_codes != time_codes {
                return Err(Error::bad_input(
                    path,
                    format!(
                        "{}: sampled at other times than {} ({} against {} samples)",
                        m.path,
                        cloth[0].path,
                        m.time_codes.len(),
                        time_codes.len()
                    ),
                ));
            }
            let base = anim.frames[0].len();
            let n = m.frames.first().map_or(0, Vec::len);
            anim.parts.push((m.path.clone(), base..base + n));
            anim.triangles.extend(
                m.triangles()
                    .into_iter()
                    .map(|t| t.map(|i| i + base as u32)),
            );
            for (out, f) in anim.frames.iter_mut().zip(&m.frames) {
                out.extend(f.iter().map(|p| p.cast::<f64>()));
            }
        }
        if anim.time_codes.is_empty() {
            anim.time_codes.push(stage.start);
        }
        Ok(anim)
    }

    /// A fine animation: a `clothsr lab dataset` directory's fine frames from time code `start`
    /// on ([`Animation::read_dataset`]), else a USD file ([`Animation::read_usd`]).
    pub fn read(path: &Path, start: f64) -> Result<Animation> {
        if path.is_dir() {
            Animation::read_dataset(path, start)
        } else {
            Animation::read_usd(path)
        }
    }

    /// The fine simulation of a `clothsr lab dataset` directory: frame k (k = 1..) at time code
    /// `start + k` (a run's frame k starts from the same scene frame); the rest frame is not
    /// stored.
    pub fn read_dataset(dir: &Path, start: f64) -> Result<Animation> {
        let manifest = crate::data::read_manifest(dir)?;
        let mesh = crate::data::read_fine_mesh(dir, &manifest)?;
        let n = mesh.num_vertices();
        let mut frames = Vec::with_capacity(manifest.frames_done);
        for k in 1..=manifest.frames_done {
            let (_, x) = crate::data::read_frame_positions(dir, k)?.fine_x;
            if x.len() != 3 * n {
                return Err(Error::bad_input(
                    dir,
                    format!("frame {k} has {} fine values for {n} vertices", x.len()),
                ));
            }
            frames.push(
                x.chunks_exact(3)
                    .map(|c| Vector3::new(c[0] as f64, c[1] as f64, c[2] as f64))
                    .collect(),
            );
        }
        if frames.is_empty() {
            return Err(Error::bad_input(dir, "the data set has no frame yet"));
        }
        Ok(Animation {
            parts: vec![("fine".into(), 0..n)],
            triangles: mesh.triangles,
            time_codes: (1..=frames.len()).map(|k| start + k as f64).collect(),
            frames,
        })
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.frames.first().map_or(0, Vec::len)
    }

    /// Index of the frame at `time_code`.
    pub fn frame_at(&self, time_code: f64) -> Option<usize> {
        self.time_codes
            .iter()
            .position(|&t| (t - time_code).abs() < 1e-6)
    }

    /// Checks that `other` is the same cloth mesh as `self`: the same vertex count and the
    /// same triangles (so vertex k is the same material point in both).
    pub fn check_same_cloth(&self, other: &Animation, path: &Path) -> Result<()> {
        if self.num_vertices() != other.num_vertices() || self.triangles != other.triangles {
            let names = |a: &Animation| -> Vec<(String, usize)> {
                a.parts
                    .iter()
                    .map(|(n, r)| (n.rsplit('/').next().unwrap_or(n).to_string(), r.len()))
                    .collect()
            };
            return Err(Error::bad_input(
                path,
                format!(
                    "its cloth meshes do not match the ground truth's: {} against {} \
                     (were both made at the same edge length from the same scene?)",
                    describe(&names(other)),
                    describe(&names(self))
                ),
            ));
        }
        Ok(())
    }
}

fn describe(parts: &[(String, usize)]) -> String {
    parts
        .iter()
        .map(|(n, k)| format!("{n} ({k} vertices)"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// How deep inside a body [`Bodies::inside`] looks for cloth, m: deeper points are not found.
pub const INSIDE_SEARCH_M: f64 = 0.02;

/// The collision bodies of a stage (meshes with the collider role: `clothsr run` writes its
/// scene's colliders beside the garments), for measuring how far cloth goes into them.
#[derive(Debug, Clone, PartialEq)]
pub struct Bodies {
    /// The bodies, their sample times in time codes.
    bodies: Vec<crate::scene::Collider>,
}

impl Bodies {
    /// The colliders of a USD file (none is not an error: `is_empty` then).
    pub fn read_usd(path: &Path) -> Result<Bodies> {
        let stage = read_usd(path)?;
        let bodies = stage
            .meshes
            .into_iter()
            .filter(|m| m.role == MeshRole::Collider && !m.frames.is_empty())
            .map(|m| crate::scene::Collider {
                name: m.name.clone(),
                triangles: m.triangles(),
                times_s: if m.time_codes.len() == m.frames.len() {
                    m.time_codes.clone()
                } else {
                    vec![0.0]
                },
                frames: if m.time_codes.len() == m.frames.len() {
                    m.frames
                } else {
                    m.frames.into_iter().take(1).collect()
                },
            })
            .collect();
        Ok(Bodies { bodies })
    }

    /// Whether the stage had no collider.
    pub fn is_empty(&self) -> bool {
        self.bodies.is_empty()
    }

    /// How many of the points `x`, at time code `t`, lie inside a body (the simulator's sign
    /// test, [`crate::sim::collide::count_inside`], up to [`INSIDE_SEARCH_M`] deep), how many
    /// of those where the body overlaps itself, and the deepest. A body between two samples is
    /// interpolated linearly, as the simulator does (an avatar sampled every other frame moves
    /// centimetres in one).
    pub fn inside(&self, x: &[Vector3<f64>], t: f64) -> PushOut {
        let points: Vec<Vec<Vector3<f64>>> = self
            .bodies
            .iter()
            .map(|b| {
                let mut p = Vec::new();
                b.positions_at(t, &mut p);
                p
            })
            .collect();
        let colliders: Vec<crate::sim::collide::Collider<'_>> = points
            .iter()
            .zip(&self.bodies)
            .map(|(p, b)| (p.as_slice(), b.triangles.as_slice()))
            .collect();
        crate::sim::collide::count_inside(x, &colliders, INSIDE_SEARCH_M)
    }
}

/// What an output holds that no ground truth is needed to judge ([`health`]): points that are
/// not finite, cloth inside the bodies, cloth through cloth, and how far any vertex moved in
/// one frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Health {
    /// Frames read.
    pub frames: usize,
    /// Point coordinates that are NaN or infinite, over all frames.
    pub non_finite: usize,
    /// Frames with at least one vertex inside a body.
    pub frames_inside: usize,
    /// Vertices inside a body, summed over the frames.
    pub inside: usize,
    /// Of those, vertices where the body overlaps itself (inside two of its parts at once, as
    /// where a walking avatar's thighs pass into each other): no place outside is near them.
    pub in_overlap: usize,
    /// The deepest vertex inside a body, m.
    pub deepest_m: f64,
    /// The largest distance a vertex moved between two consecutive frames, m.
    pub max_move_m: f64,
    /// The time code of the frame that move ended at.
    pub max_move_time: f64,
    /// Cloth through cloth: edges passing through a triangle they share no vertex (nor a
    /// coincident one, as across a welded seam) with, summed over the frames.
    pub crossings: usize,
    /// Of those, an edge of one garment through a triangle of another: a layer through a layer.
    pub crossings_between: usize,
    /// Frames with any crossing.
    pub frames_crossing: usize,
    /// The most crossings in one frame.
    pub max_crossings: usize,
}

/// Positions closer than this are one point (a welded seam's two vertices), m.
const COINCIDENT_M: f64 = 1e-7;

/// Edges of `anim`'s cloth through its triangles at positions `x` ([`Health::crossings`]):
/// (all, between two garments).
pub fn crossings(anim: &Animation, x: &[Vector3<f64>]) -> (usize, usize) {
    let edges = crate::mesh::unique_edges(&anim.triangles);
    let near =
        |a: u32, b: u32| (x[a as usize] - x[b as usize]).norm_squared() < COINCIDENT_M.powi(2);
    let found = crate::sim::collide::edge_triangle_crossings(x, &anim.triangles, &edges, |e, t| {
        !e.iter().any(|&a| t.iter().any(|&b| near(a, b)))
    });
    let part = |v: u32| {
        anim.parts
            .iter()
            .position(|(_, r)| r.contains(&(v as usize)))
    };
    let between = found
        .iter()
        .filter(|(e, t)| part(e[0]) != part(t[0]))
        .count();
    (found.len(), between)
}

/// The [`Health`] of `anim` against the bodies of its scene.
pub fn health(anim: &Animation, bodies: &Bodies) -> Health {
    let mut h = Health {
        frames: anim.frames.len(),
        ..Health::default()
    };
    for (k, (x, &t)) in anim.frames.iter().zip(&anim.time_codes).enumerate() {
        h.non_finite += x
            .iter()
            .map(|p| p.iter().filter(|c| !c.is_finite()).count())
            .sum::<usize>();
        if !bodies.is_empty() {
            let r = bodies.inside(x, t);
            h.inside += r.inside;
            h.in_overlap += r.in_overlap;
            h.frames_inside += usize::from(r.inside > 0);
            h.deepest_m = h.deepest_m.max(r.max_depth_m);
        }
        if !anim.triangles.is_empty() {
            let (all, between) = crossings(anim, x);
            h.crossings += all;
            h.crossings_between += between;
            h.frames_crossing += usize::from(all > 0);
            h.max_crossings = h.max_crossings.max(all);
        }
        if let Some(prev) = k.checked_sub(1).map(|j| &anim.frames[j]) {
            let moved = x
                .iter()
                .zip(prev)
                .map(|(a, b)| (a - b).norm())
                .fold(0.0, f64::max);
            if moved > h.max_move_m {
                h.max_move_m = moved;
                h.max_move_time = t;
            }
        }
    }
    h
}

/// Errors of one frame against the ground truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameMetrics {
    /// Time code of the frame.
    pub time_code: f64,
    /// Mean vertex distance, mm.
    pub mean_mm: f64,
    /// Largest vertex distance, mm.
    pub max_mm: f64,
    /// Standard deviation of the vertex distances, mm.
    pub std_mm: f64,
    /// Mean angle between predicted and true vertex normals, degrees.
    pub normal_deg: f64,
    /// Mean ‖x_{t+1} − 2x_t + x_{t−1}‖ of the prediction, mm (None at the first and last frame).
    pub jitter_mm: Option<f64>,
    /// The same of the ground truth, mm.
    pub gt_jitter_mm: Option<f64>,
    /// The 1-Wasserstein distance between the distributions of the prediction's and the ground
    /// truth's bend angles (the angle between the normals of two triangles sharing an edge),
    /// degrees: how far the folds and wrinkles differ in kind, wherever they lie.
    pub bend_w1_deg: f64,
    /// Mean bend angle of the prediction, degrees (more wrinkled: larger).
    pub bend_mean_deg: f64,
    /// The same of the ground truth, degrees.
    pub gt_bend_mean_deg: f64,
}

/// Compares `pred` with `gt` at every time code they share. Fails when they share none or
/// their meshes differ.
pub fn compare(gt: &Animation, pred: &Animation, pred_path: &Path) -> Result<Vec<FrameMetrics>> {
    gt.check_same_cloth(pred, pred_path)?;
    let pairs: Vec<(usize, usize)> = pred
        .time_codes
        .iter()
        .enumerate()
        .filter_map(|(j, &t)| gt.frame_at(t).map(|i| (i, j)))
        .collect();
    if pairs.is_empty() {
        return Err(Error::bad_input(
            pred_path,
            format!(
                "no time code in common with the ground truth (prediction {:?}..{:?}, ground truth {:?}..{:?})",
                pred.time_codes.first(),
                pred.time_codes.last(),
                gt.time_codes.first(),
                gt.time_codes.last()
            ),
        ));
    }
    let jitter = |a: &Animation, k: usize| -> Option<f64> {
        (k > 0 && k + 1 < a.frames.len())
            .then(|| jitter_m(&a.frames[k - 1], &a.frames[k], &a.frames[k + 1]) * 1e3)
    };
    let hinges = hinges(&gt.triangles);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    Ok(pairs
        .iter()
        .map(|&(i, j)| {
            let (g, p) = (&gt.frames[i], &pred.frames[j]);
            let (mean_m, max, std) = mean_max_std(&vertex_errors(g, p));
            let (bend_g, bend_p) = (
                bend_angles_deg(&gt.triangles, &hinges, g),
                bend_angles_deg(&gt.triangles, &hinges, p),
            );
            FrameMetrics {
                time_code: gt.time_codes[i],
                mean_mm: mean_m * 1e3,
                max_mm: max * 1e3,
                std_mm: std * 1e3,
                normal_deg: normal_angle_deg(&gt.triangles, g, p),
                jitter_mm: jitter(pred, j),
                gt_jitter_mm: jitter(gt, i),
                bend_w1_deg: wasserstein1_sorted(&bend_p, &bend_g),
                bend_mean_deg: mean(&bend_p),
                gt_bend_mean_deg: mean(&bend_g),
            }
        })
        .collect())
}

/// A prediction measured against two ground truths that share a start: a fine simulation and
/// its twin (`clothsr lab fork`: the same simulation continued from one of its frames with the
/// garment moved a fraction of a millimetre). Neither is more right than the other, so no
/// prediction made from their shared start can be closer to both than half their distance on
/// average: per vertex and frame |a − p| + |p − b| ≥ |a − b| (the triangle inequality).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FloorBound {
    /// Frames measured: the prediction's frames that both ground truths have.
    pub frames: usize,
    /// The two ground truths' mean vertex distance over those frames (the floor), mm.
    pub floor_mm: f64,
    /// The prediction's mean vertex error against the ground truth, mm.
    pub against_gt_mm: f64,
    /// The same against the twin, mm.
    pub against_twin_mm: f64,
}

impl FloorBound {
    /// The least mean error, over the two ground truths, of any prediction: half the floor, mm.
    pub fn least_mm(&self) -> f64 {
        0.5 * self.floor_mm
    }

    /// The prediction's mean error over the two ground truths, mm (never below
    /// [`FloorBound::least_mm`], but for rounding).
    pub fn two_truths_mm(&self) -> f64 {
        0.5 * (self.against_gt_mm + self.against_twin_mm)
    }
}

/// One frame of a prediction against a ground truth and its twin ([`floor_frames`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FloorFrame {
    /// Its time code.
    pub time_code: f64,
    /// The two ground truths' mean vertex distance, mm.
    pub floor_mm: f64,
    /// The prediction's mean vertex error against the ground truth, mm.
    pub against_gt_mm: f64,
    /// The same against the twin, mm.
    pub against_twin_mm: f64,
}

/// The floor of `gt` and its `twin` and `pred`'s errors against both, per frame of the
/// prediction that both have. Fails, naming the file, when the twin or the prediction is
/// another cloth or no frame is shared.
pub fn floor_frames(
    gt: &Animation,
    twin: &Animation,
    twin_path: &Path,
    pred: &Animation,
    pred_path: &Path,
) -> Result<Vec<FloorFrame>> {
    gt.check_same_cloth(twin, twin_path)?;
    gt.check_same_cloth(pred, pred_path)?;
    let frames: Vec<FloorFrame> = pred
        .time_codes
        .iter()
        .enumerate()
        .filter_map(|(j, &t)| {
            let (i, k) = (gt.frame_at(t)?, twin.frame_at(t)?);
            Some(FloorFrame {
                time_code: t,
                floor_mm: mean_distance_mm(&gt.frames[i], &twin.frames[k]),
                against_gt_mm: mean_distance_mm(&gt.frames[i], &pred.frames[j]),
                against_twin_mm: mean_distance_mm(&twin.frames[k], &pred.frames[j]),
            })
        })
        .collect();
    if frames.is_empty() {
        return Err(Error::bad_input(
            twin_path,
            "no frame of the prediction is in both the ground truth and this twin",
        ));
    }
    Ok(frames)
}

impl FloorBound {
    /// The means over `frames` (not empty: [`floor_frames`] gives at least one).
    pub fn of(frames: &[FloorFrame]) -> FloorBound {
        let n = frames.len().max(1) as f64;
        let avg = |f: fn(&FloorFrame) -> f64| frames.iter().map(f).sum::<f64>() / n;
        FloorBound {
            frames: frames.len(),
            floor_mm: avg(|f| f.floor_mm),
            against_gt_mm: avg(|f| f.against_gt_mm),
            against_twin_mm: avg(|f| f.against_twin_mm),
        }
    }
}

/// The floor of `gt` and its `twin` and `pred`'s errors against both, over the prediction's
/// frames that both have ([`FloorBound`], [`floor_frames`]).
pub fn floor_bound(
    gt: &Animation,
    twin: &Animation,
    twin_path: &Path,
    pred: &Animation,
    pred_path: &Path,
) -> Result<FloorBound> {
    Ok(FloorBound::of(&floor_frames(
        gt, twin, twin_path, pred, pred_path,
    )?))
}

/// A series' label and its per-frame metrics.
pub type Series = (String, Vec<FrameMetrics>);

/// The errors against `gt` of a prediction and of baselines (`series`: label, animation and
/// its file, the prediction first), per frame. A baseline counts over the prediction's frames
/// only, so that the ratios compare like with like (a fork's frames before it was moved count
/// as zero there too).
pub fn measure(gt: &Animation, series: &[(String, &Animation, &Path)]) -> Result<Vec<Series>> {
    let mut out: Vec<Series> = Vec::with_capacity(series.len());
    for (name, anim, path) in series {
        let mut m = compare(gt, anim, path)?;
        if let Some((_, pred)) = out.first() {
            m.retain(|f| {
                pred.iter()
                    .any(|p| (p.time_code - f.time_code).abs() < 1e-6)
            });
        }
        out.push((name.clone(), m));
    }
    Ok(out)
}

/// Averages over frames of one series.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Summary {
    /// Frames compared.
    pub frames: usize,
    /// Mean of the per-frame mean errors, mm.
    pub mean_mm: f64,
    /// Largest per-frame max error, mm.
    pub max_mm: f64,
    /// Mean of the per-frame standard deviations, mm.
    pub std_mm: f64,
    /// Mean normal angle error, degrees.
    pub normal_deg: f64,
    /// Mean jitter of the prediction, mm.
    pub jitter_mm: f64,
    /// Mean jitter of the ground truth over the same frames, mm.
    pub gt_jitter_mm: f64,
    /// Mean distance between the bend-angle distributions, degrees.
    pub bend_w1_deg: f64,
    /// Mean bend angle of the prediction, degrees.
    pub bend_mean_deg: f64,
    /// Mean bend angle of the ground truth over the same frames, degrees.
    pub gt_bend_mean_deg: f64,
}

/// The summary of a series of frames.
pub fn summarise(m: &[FrameMetrics]) -> Summary {
    let n = m.len().max(1) as f64;
    let avg = |f: &dyn Fn(&FrameMetrics) -> f64| m.iter().map(f).sum::<f64>() / n;
    let jit: Vec<(f64, f64)> = m
        .iter()
        .filter_map(|x| Some((x.jitter_mm?, x.gt_jitter_mm?)))
        .collect();
    let k = jit.len().max(1) as f64;
    Summary {
        frames: m.len(),
        mean_mm: avg(&|x| x.mean_mm),
        max_mm: m.iter().map(|x| x.max_mm).fold(0.0, f64::max),
        std_mm: avg(&|x| x.std_mm),
        normal_deg: avg(&|x| x.normal_deg),
        jitter_mm: jit.iter().map(|j| j.0).sum::<f64>() / k,
        gt_jitter_mm: jit.iter().map(|j| j.1).sum::<f64>() / k,
        bend_w1_deg: avg(&|x| x.bend_w1_deg),
        bend_mean_deg: avg(&|x| x.bend_mean_deg),
        gt_bend_mean_deg: avg(&|x| x.gt_bend_mean_deg),
    }
}

/// Writes every series' per-frame metrics as one CSV (a `series` column names each), atomically.
pub fn write_csv(path: &Path, series: &[(String, Vec<FrameMetrics>)]) -> Result<()> {
    let mut s =
        String::from("series,time_code,mean_mm,max_mm,std_mm,normal_deg,jitter_mm,gt_jitter_mm,bend_w1_deg,bend_mean_deg,gt_bend_mean_deg\n");
    let opt = |v: Option<f64>| v.map(|x| format!("{x:.6}")).unwrap_or_default();
    for (name, ms) in series {
        for m in ms {
            s.push_str(&format!(
                "{name},{},{:.6},{:.6},{:.6},{:.6},{},{},{:.4},{:.4},{:.4}\n",
                m.time_code,
                m.mean_mm,
                m.max_mm,
                m.std_mm,
                m.normal_deg,
                opt(m.jitter_mm),
                opt(m.gt_jitter_mm),
                m.bend_w1_deg,
                m.bend_mean_deg,
                m.gt_bend_mean_deg
            ));
        }
    }
    crate::io::write_atomic(path, s.as_bytes())
}

/// Plots mean error over time (±1 std) of every series to a PNG (matplotlib through the bridge).
pub fn plot(path: &Path, series: &[(String, Vec<FrameMetrics>)], title: &str) -> Result<()> {
    if path.extension().and_then(|e| e.to_str()) != Some("png") {
        return Err(Error::bad_input(path, "the plot must be a .png file"));
    }
    let frames: Vec<f64> = series
        .first()
        .map(|(_, m)| m.iter().map(|x| x.time_code).collect())
        .unwrap_or_default();
    let data: Vec<(String, Vec<f64>, Vec<f64>)> = series
        .iter()
        .map(|(n, m)| {
            (
                n.clone(),
                m.iter().map(|x| x.mean_mm).collect(),
                m.iter().map(|x| x.std_mm).collect(),
            )
        })
        .collect();
    let p = path
        .to_str()
        .ok_or_else(|| Error::bad_input(path, "the path is not valid UTF-8"))?
        .to_string();
    use pyo3::types::PyAnyMethods;
    crate::io::python::with_bridge(|_py, m| {
        m.call_method1("plot_errors", (p.as_str(), frames, data, title))?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ball sampled at time codes 0 and 2, moved 0.2 m along x between them: at time code 1
    /// it is half way, as the simulator interpolates it. A point at its centre then is inside
    /// (0.1 m deep, beyond the 20 mm search: not found), one 5 mm inside its surface is found
    /// 5 mm deep, and neither sample alone would say so.
    #[test]
    fn bodies_between_samples_are_interpolated() {
        let ball = crate::scene::Collider::sphere("ball", Vector3::zeros(), 0.1, 3);
        let mut moved = ball.frames[0].clone();
        moved.iter_mut().for_each(|p| p.x += 0.2);
        let bodies = Bodies {
            bodies: vec![crate::scene::Collider {
                times_s: vec![0.0, 2.0],
                frames: vec![ball.frames[0].clone(), moved],
                ..ball
            }],
        };
        let near_top = Vector3::new(0.1, 0.095, 0.0);
        let r = bodies.inside(&[near_top, Vector3::new(0.1, 0.0, 0.0)], 1.0);
        let depth = r.max_depth_m;
        assert_eq!((r.inside, r.in_overlap), (1, 0));
        // The icosphere's faces lie a little inside the sphere: 5 mm less that.
        assert!(depth > 0.004 && depth < 0.005, "{depth}");
        assert_eq!(bodies.inside(&[near_top], 0.0), PushOut::default());
        assert_eq!(bodies.inside(&[near_top], 2.0), PushOut::default());
    }

    /// Three frames of two points over a still ball: one point dips 5 mm into it in the second
    /// frame and jumps 30 mm in the third, where the other is NaN.
    #[test]
    fn health_counts_what_is_not_finite_inside_or_jumping() {
        let ball = crate::scene::Collider::sphere("ball", Vector3::zeros(), 0.1, 3);
        let bodies = Bodies { bodies: vec![ball] };
        let (above, far) = (Vector3::new(0.0, 0.12, 0.0), Vector3::new(1.0, 0.0, 0.0));
        let dipped = Vector3::new(0.0, 0.095, 0.0);
        let anim = Animation {
            parts: vec![("/cloth".into(), 0..2)],
            triangles: Vec::new(),
            time_codes: vec![0.0, 1.0, 2.0],
            frames: vec![
                vec![above, far],
                vec![dipped, far],
                vec![
                    dipped + Vector3::new(0.03, 0.0, 0.0),
                    Vector3::new(f64::NAN, 0.0, 0.0),
                ],
            ],
        };
        let h = health(&anim, &bodies);
        assert_eq!(h.frames, 3);
        assert_eq!(h.non_finite, 1);
        assert_eq!((h.frames_inside, h.inside), (2, 2));
        assert!(h.deepest_m > 0.004 && h.deepest_m < 0.0051, "{h:?}");
        assert!((h.max_move_m - 0.03).abs() < 1e-12, "{h:?}");
        assert_eq!(h.max_move_time, 2.0);
    }

    /// Two garments of one triangle each, crossed in the second frame only; a third triangle
    /// welded to the first along a seam (coincident vertices) is not a crossing.
    #[test]
    fn health_counts_cloth_through_cloth_and_layers_through_layers() {
        let v = |x: f64, y: f64, z: f64| Vector3::new(x, y, z);
        let flat = [v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0), v(0.0, 0.0, 1.0)];
        // Shares the seam 0–2 of the first (its own coincident vertices 6, 7), folded up.
        let seam = [v(0.0, 0.0, 0.0), v(0.0, 0.0, 1.0), v(-0.5, 0.5, 0.5)];
        let frame = |lift: f64| -> Vec<Vector3<f64>> {
            let upright = [
                v(0.2, lift, 0.2),
                v(0.3, lift + 1.0, 0.2),
                v(0.2, lift + 1.0, 0.3),
            ];
            flat.iter().chain(&upright).chain(&seam).copied().collect()
        };
        let anim = Animation {
            parts: vec![
                ("/a".into(), 0..3),
                ("/b".into(), 3..6),
                ("/a2".into(), 6..9),
            ],
            triangles: vec![[0, 1, 2], [3, 4, 5], [6, 7, 8]],
            time_codes: vec![0.0, 1.0],
            frames: vec![frame(0.1), frame(-0.5)],
        };
        let h = health(&anim, &Bodies { bodies: Vec::new() });
        // Edges 3–4 and 3–5 of the upright triangle pass through the flat one.
        assert_eq!((h.crossings, h.crossings_between), (2, 2), "{h:?}");
        assert_eq!((h.frames_crossing, h.max_crossings), (1, 2));
        // One garment folded through itself: a crossing, not between garments.
        let mut one = anim.clone();
        one.parts = vec![("/a".into(), 0..9)];
        assert_eq!(crossings(&one, &one.frames[1]), (2, 0));
    }

    #[test]
    fn metrics_of_a_known_offset_and_a_known_acceleration() {
        let tris = vec![[0u32, 1, 2]];
        let gt = vec![
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
        ];
        // Moved 3 mm along the normal: every vertex 3 mm off, normals unchanged.
        let pred: Vec<_> = gt
            .iter()
            .map(|p| p + Vector3::new(0.0, 0.0, 0.003))
            .collect();
        let e = vertex_errors(&gt, &pred);
        let (mean, max, std) = mean_max_std(&e);
        assert!((mean - 0.003).abs() < 1e-12 && (max - 0.003).abs() < 1e-12 && std < 1e-12);
        assert!(normal_angle_deg(&tris, &gt, &pred) < 1e-9);
        // One vertex lifted until the triangle tilts 45° about the x axis.
        let mut tilted = gt.clone();
        tilted[2].z = 1.0;
        let a = normal_angle_deg(&tris, &gt, &tilted);
        assert!((a - 45.0).abs() < 1e-9, "{a}");
        // Constant acceleration a: x_{t+1} − 2x_t + x_{t−1} = a·Δt² exactly.
        let at = |t: f64| -> Vec<Vector3<f64>> {
            gt.iter()
                .map(|p| p + Vector3::new(0.0, -0.5 * 9.81 * t * t, 0.0))
                .collect()
        };
        let dt = 0.1;
        let j = jitter_m(&at(0.0), &at(dt), &at(2.0 * dt));
        assert!((j - 9.81 * dt * dt).abs() < 1e-12, "{j}");
    }

    #[test]
    fn summary_averages_frames_and_skips_missing_jitter() {
        let f = |t: f64, mean: f64, j: Option<f64>| FrameMetrics {
            time_code: t,
            mean_mm: mean,
            max_mm: 2.0 * mean,
            std_mm: 0.5,
            normal_deg: 1.0,
            jitter_mm: j,
            gt_jitter_mm: j.map(|x| 2.0 * x),
            bend_w1_deg: mean,
            bend_mean_deg: 10.0,
            gt_bend_mean_deg: 12.0,
        };
        let s = summarise(&[f(1.0, 1.0, None), f(2.0, 3.0, Some(0.2)), f(3.0, 2.0, None)]);
        assert_eq!(s.frames, 3);
        assert!((s.mean_mm - 2.0).abs() < 1e-12);
        assert!((s.max_mm - 6.0).abs() < 1e-12);
        assert!((s.jitter_mm - 0.2).abs() < 1e-12 && (s.gt_jitter_mm - 0.4).abs() < 1e-12);
        assert!((s.bend_w1_deg - 2.0).abs() < 1e-12);
        assert!(
            (s.bend_mean_deg - 10.0).abs() < 1e-12 && (s.gt_bend_mean_deg - 12.0).abs() < 1e-12
        );
    }

    #[test]
    fn no_prediction_is_closer_to_two_twins_than_half_their_distance() {
        let anim = |frames: Vec<Vec<Vector3<f64>>>, t0: f64| Animation {
            parts: vec![("/cloth".into(), 0..3)],
            triangles: vec![[0, 1, 2]],
            time_codes: (0..frames.len()).map(|k| t0 + k as f64).collect(),
            frames,
        };
        let base = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
        ];
        let moved = |d: Vector3<f64>| -> Vec<Vector3<f64>> { base.iter().map(|p| p + d).collect() };
        // Frames 1..=4; the twin is the ground truth moved 4 mm along x from frame 2 on (frame
        // 1 shared), and has no frame 4.
        let gt = anim((0..4).map(|_| moved(Vector3::zeros())).collect(), 1.0);
        let twin = anim(
            (0..3)
                .map(|k| moved(Vector3::new(if k == 0 { 0.0 } else { 0.004 }, 0.0, 0.0)))
                .collect(),
            1.0,
        );
        // A prediction halfway between them, and frames 0..=4 (frame 0 in neither).
        let half = anim(
            (0..5)
                .map(|_| moved(Vector3::new(0.002, 0.0, 0.0)))
                .collect(),
            0.0,
        );
        let (p, q) = (Path::new("twin"), Path::new("pred"));
        let b = floor_bound(&gt, &twin, p, &half, q).expect("shared frames");
        // Frames 1, 2, 3: the floor 0, 4, 4 mm.
        assert_eq!(b.frames, 3);
        assert!((b.floor_mm - 8.0 / 3.0).abs() < 1e-9, "{b:?}");
        assert!((b.least_mm() - 4.0 / 3.0).abs() < 1e-9);
        // Halfway is 2 mm from each where they differ, and meets the bound there; on the shared
        // frame it is 2 mm from both where the bound is 0.
        assert!((b.against_gt_mm - 2.0).abs() < 1e-9 && (b.against_twin_mm - 2.0).abs() < 1e-9);
        assert!(b.two_truths_mm() >= b.least_mm());
        // Predictions off the line between them, or nearer one truth, stay above the bound.
        for d in [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.004, 0.0, 0.0),
            Vector3::new(0.001, 0.003, -0.002),
            Vector3::new(-0.01, 0.0, 0.0),
        ] {
            let pred = anim((0..4).map(|_| moved(d)).collect(), 1.0);
            let b = floor_bound(&gt, &twin, p, &pred, q).expect("shared frames");
            assert!(b.two_truths_mm() >= b.least_mm() - 1e-12, "{d:?}: {b:?}");
        }
        // Nothing shared: refused, naming the twin.
        let late = anim(vec![moved(Vector3::zeros())], 9.0);
        let err = floor_bound(&gt, &late, p, &half, q).expect_err("no shared frame");
        assert!(err.to_string().contains("twin"), "{err}");
    }
}
