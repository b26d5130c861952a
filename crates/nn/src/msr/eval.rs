//! Evaluating the MSR module on a data set: super-resolve its M_int sequence frame by frame
//! (each frame initialised with the previous frame's output) and compare the fine mesh with
//! the fine simulation, next to the upsampled coarse mesh (barycentric interpolation of M_int
//! at the fine vertices' material points, [`clothsr_geometry::transfer::Transfer::upsample`]) and the
//! Phong-tessellated one ([`clothsr_geometry::transfer::Transfer::upsample_phong`]).

use std::ops::ControlFlow;

use nalgebra::Vector3;

use super::data::IsrSequence;
use super::inference::{FrameTimes, Isr, SuperResolver};
use clothsr_geometry::error::Result;
use clothsr_geometry::transfer::Transfer;

/// One frame's errors, mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameErrors {
    /// Data-set frame (1-based).
    pub frame: usize,
    /// Mean vertex distance of the SR fine mesh to the fine ground truth.
    pub sr_mm: f64,
    /// Largest vertex distance of the SR fine mesh.
    pub sr_max_mm: f64,
    /// Mean vertex distance of the upsampled M_int (piecewise-linear).
    pub upsampled_mm: f64,
    /// Mean vertex distance of M_int upsampled by Phong tessellation with the model's blend.
    pub phong_mm: f64,
    /// Mean angle between the SR mesh's vertex normals and the fine simulation's, degrees.
    pub sr_normal_deg: f64,
    /// The same for the Phong-upsampled M_int.
    pub phong_normal_deg: f64,
    /// The 1-Wasserstein distance between the SR mesh's bend angles and the fine simulation's
    /// ([`clothsr_geometry::metrics::bend_angles_deg`]), degrees: its folds and wrinkles in kind.
    pub sr_bend_w1_deg: f64,
    /// The same for the upsampled M_int.
    pub upsampled_bend_w1_deg: f64,
    /// Temporal jitter ([`clothsr_geometry::metrics::jitter_m`], mean ‖x_t − 2x_{t−1} + x_{t−2}‖ over
    /// vertices) of the SR meshes, the Phong-upsampled M_int and the fine simulation, mm;
    /// from the third frame on.
    pub jitter_mm: Option<Jitter>,
    /// Time of the SR frame.
    pub times: FrameTimes,
}

/// Temporal jitter of a frame, mm (the second difference over the last three frames).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Jitter {
    /// The SR meshes.
    pub sr: f64,
    /// The Phong-upsampled M_int.
    pub phong: f64,
    /// The fine simulation (the ground truth's own motion).
    pub gt: f64,
    /// The SR meshes' second difference against the fine simulation's (mean ‖a_SR − a_gt‖):
    /// temporal noise that the ground truth's motion does not have.
    pub sr_err: f64,
    /// The same for the Phong-upsampled M_int.
    pub phong_err: f64,
}

/// Errors of a whole sequence.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SequenceErrors {
    /// Per frame, in order.
    pub frames: Vec<FrameErrors>,
}

impl SequenceErrors {
    /// Mean over frames of the SR error, mm.
    pub fn mean_sr_mm(&self) -> f64 {
        mean(self.frames.iter().map(|f| f.sr_mm))
    }

    /// Mean over frames of the upsampled-coarse error, mm.
    pub fn mean_upsampled_mm(&self) -> f64 {
        mean(self.frames.iter().map(|f| f.upsampled_mm))
    }

    /// Mean over frames of the Phong-upsampled error, mm.
    pub fn mean_phong_mm(&self) -> f64 {
        mean(self.frames.iter().map(|f| f.phong_mm))
    }

    /// Mean over frames of the normal-angle error of SR and of Phong, degrees.
    pub fn mean_normal_deg(&self) -> (f64, f64) {
        (
            mean(self.frames.iter().map(|f| f.sr_normal_deg)),
            mean(self.frames.iter().map(|f| f.phong_normal_deg)),
        )
    }

    /// Mean over frames of the bend-angle distance of SR and of the upsampled M_int, degrees.
    pub fn mean_bend_w1_deg(&self) -> (f64, f64) {
        (
            mean(self.frames.iter().map(|f| f.sr_bend_w1_deg)),
            mean(self.frames.iter().map(|f| f.upsampled_bend_w1_deg)),
        )
    }

    /// Mean jitter over the frames that have one (SR, Phong, ground truth), mm.
    pub fn mean_jitter_mm(&self) -> Option<Jitter> {
        let j: Vec<Jitter> = self.frames.iter().filter_map(|f| f.jitter_mm).collect();
        (!j.is_empty()).then(|| Jitter {
            sr: mean(j.iter().map(|j| j.sr)),
            phong: mean(j.iter().map(|j| j.phong)),
            gt: mean(j.iter().map(|j| j.gt)),
            sr_err: mean(j.iter().map(|j| j.sr_err)),
            phong_err: mean(j.iter().map(|j| j.phong_err)),
        })
    }

    /// Mean time per frame and the network's share of it.
    pub fn mean_times(&self) -> (f64, f64) {
        let total = mean(self.frames.iter().map(|f| f.times.total_s()));
        let net = mean(self.frames.iter().map(|f| f.times.network_s));
        (total, if total > 0.0 { net / total } else { 0.0 })
    }
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    s / n.max(1) as f64
}

/// Mean and max vertex distance, mm.
pub fn vertex_error_mm(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> (f64, f64) {
    let (mean_m, max_m, _) =
        clothsr_geometry::metrics::mean_max_std(&clothsr_geometry::metrics::vertex_errors(a, b));
    (mean_m * 1e3, max_m * 1e3)
}

/// Super-resolves `seq`'s frames in order and measures them; `progress(done, total)` may stop
/// early (`ControlFlow::Break`) and the frames so far are returned. With `teacher_forcing`
/// every frame after the first is initialised with the fine simulation's previous frame
/// instead of the network's own output (a diagnostic: the network's error without its own
/// errors fed back).
pub fn evaluate(
    seq: &IsrSequence,
    isr: &Isr,
    teacher_forcing: bool,
    mut progress: impl FnMut(usize, usize) -> ControlFlow<()>,
) -> Result<SequenceErrors> {
    let conditions = seq.conditions.clone().unwrap_or_default();
    let mut sr = SuperResolver::new(isr, &seq.coarse_mesh, &seq.fine_mesh, &conditions)?;
    let transfer = Transfer::new(&seq.coarse_mesh, &seq.fine_mesh)?;
    let hinges = clothsr_geometry::metrics::hinges(&seq.fine_mesh.triangles);
    let mut out = SequenceErrors::default();
    // The last two frames' SR and Phong meshes, for the jitter.
    type Positions = Vec<Vector3<f64>>;
    let mut history: Vec<(Positions, Positions)> = Vec::new();
    for (k, (int, gt)) in seq.int_x.iter().zip(&seq.fine_x).enumerate() {
        if teacher_forcing && k > 0 {
            sr.set_previous(&seq.fine_mesh, &seq.fine_x[k - 1], &seq.int_x[k - 1])?;
        }
        let fine = sr.frame(int)?;
        let (sr_mm, sr_max_mm) = vertex_error_mm(&fine, gt);
        let upsampled = transfer.upsample(int);
        let (upsampled_mm, _) = vertex_error_mm(&upsampled, gt);
        let bends = |x: &[Vector3<f64>]| {
            clothsr_geometry::metrics::bend_angles_deg(&seq.fine_mesh.triangles, &hinges, x)
        };
        let gt_bends = bends(gt);
        let sr_bend_w1_deg =
            clothsr_geometry::metrics::wasserstein1_sorted(&bends(&fine), &gt_bends);
        let upsampled_bend_w1_deg =
            clothsr_geometry::metrics::wasserstein1_sorted(&bends(&upsampled), &gt_bends);
        let phong = transfer.upsample_phong(int, &seq.coarse_mesh.triangles, isr.cfg.phong_alpha);
        let (phong_mm, _) = vertex_error_mm(&phong, gt);
        let tris = &seq.fine_mesh.triangles;
        let sr_normal_deg = clothsr_geometry::metrics::normal_angle_deg(tris, gt, &fine);
        let phong_normal_deg = clothsr_geometry::metrics::normal_angle_deg(tris, gt, &phong);
        let jitter_mm = (k >= 2).then(|| {
            let ((s2, p2), (s1, p1)) = (&history[0], &history[1]);
            let (g2, g1) = (&seq.fine_x[k - 2], &seq.fine_x[k - 1]);
            let minus = |a: &[Vector3<f64>], b: &[Vector3<f64>]| -> Vec<Vector3<f64>> {
                a.iter().zip(b).map(|(a, b)| a - b).collect()
            };
            let error = |x2: &[Vector3<f64>], x1: &[Vector3<f64>], x0: &[Vector3<f64>]| {
                clothsr_geometry::metrics::jitter_m(&minus(x2, g2), &minus(x1, g1), &minus(x0, gt))
                    * 1e3
            };
            Jitter {
                sr: clothsr_geometry::metrics::jitter_m(s2, s1, &fine) * 1e3,
                phong: clothsr_geometry::metrics::jitter_m(p2, p1, &phong) * 1e3,
                gt: clothsr_geometry::metrics::jitter_m(g2, g1, gt) * 1e3,
                sr_err: error(s2, s1, &fine),
                phong_err: error(p2, p1, &phong),
            }
        });
        if history.len() == 2 {
            history.remove(0);
        }
        history.push((fine, phong));
        out.frames.push(FrameErrors {
            frame: seq.first_frame + k,
            sr_mm,
            sr_max_mm,
            upsampled_mm,
            phong_mm,
            sr_normal_deg,
            phong_normal_deg,
            sr_bend_w1_deg,
            upsampled_bend_w1_deg,
            jitter_mm,
            times: sr.times,
        });
        if progress(k + 1, seq.int_x.len()).is_break() {
            break;
        }
    }
    Ok(out)
}
