//! `clothsr::msr` ISR network: window partition/reverse and shifted-window masks, output shapes,
//! the loss against the reference finite differences, training lowers the loss and resumes,
//! save → load gives identical outputs, and super-resolution of a tiny data set is invariant to
//! moving the garment.

mod common;

use std::ops::ControlFlow;

use burn::tensor::{Tensor, TensorData};
use clothsr::data::Variation;
use clothsr::dataset::{generate, Options};
use clothsr::msr::data::IsrSequence;
use clothsr::msr::eval::evaluate;
use clothsr::msr::gradients::gradient_l1;
use clothsr::msr::inference::{
    geometry_channels, patch_input, CURVATURE_UNIT, GEOMETRY_CHANNELS, STRAIN_UNIT,
};
use clothsr::msr::model::{
    pixel_shuffle, pixel_unshuffle, relative_position_index, shift_mask, window_partition,
    window_reverse, IsrConfig,
};
use clothsr::msr::training::{
    gradient_mask, isr_loss, save_model, train, Batch, IsrTrainingConfig,
};
use clothsr::msr::{Isr, SuperResolver};
use clothsr::nn::common::default_device;
use clothsr::scene::Scene;
use nalgebra::Vector3;
use ndarray::{Array2, Array3};

fn scene() -> Scene {
    common::sheet_over_ball("silk", 0.17)
}

const FINE_M: f64 = 0.01;

/// An 8-frame data set at 40 mm / 10 mm (maps of about 32 × 32 pixels), made once.
fn dataset() -> std::path::PathBuf {
    static DIR: std::sync::OnceLock<tempfile::TempDir> = std::sync::OnceLock::new();
    let dir = DIR.get_or_init(|| {
        let dir = tempfile::tempdir().expect("tmp");
        let opts = Options {
            coarse_edge_m: 0.04,
            fine_edge_m: FINE_M,
            frames: 8,
            dress: false,
            self_collision: false,
            variation: Variation::default(),
            fast: true,
            fine_mode: clothsr::sim::step::SolverMode::Data,
            match_contact_thickness: true,
            source: None,
        };
        generate(&scene(), "test", &opts, dir.path(), |_| {}).expect("generate");
        dir
    });
    dir.path().to_path_buf()
}

fn tiny_model() -> IsrConfig {
    IsrConfig::new()
        .with_embed_dim(8)
        .with_depths(vec![2])
        .with_heads(2)
        .with_window(4)
}

fn tiny_config() -> IsrTrainingConfig {
    IsrTrainingConfig::new(tiny_model(), FINE_M)
        .with_patch(16)
        .with_steps(400)
        .with_batch(4)
        .with_lr_start(3e-3)
        .with_lr_end(1e-3)
        .with_checkpoint_every(100)
        .with_unroll_max(1)
}

/// Rewrites the `config.json` in `dir` through `edit` (as files written by older versions,
/// or edited by hand, look).
fn edit_config(dir: &std::path::Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let path = dir.join("config.json");
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).expect("read")).expect("json");
    edit(&mut json);
    std::fs::write(&path, json.to_string()).expect("write");
}

/// Removes the model setting `field` from the `config.json` in `dir`.
fn drop_model_field(dir: &std::path::Path, field: &str) {
    edit_config(dir, |json| {
        json["model"]
            .as_object_mut()
            .expect("model object")
            .remove(field);
    });
}

#[test]
fn windows_partition_and_reverse_exactly_and_shift_masks_separate_wrapped_tokens() {
    let device = default_device().expect("device");
    let (b, h, w, c, ws) = (2, 8, 12, 3, 4);
    let values: Vec<f32> = (0..b * h * w * c).map(|i| i as f32).collect();
    let x = Tensor::<4>::from_data(TensorData::new(values.clone(), [b, h, w, c]), &device);
    let win = window_partition(x.clone(), ws);
    assert_eq!(win.dims(), [b * (h / ws) * (w / ws), ws * ws, c]);
    // Window 1 of image 0 starts at pixel (0, 4).
    let v: Vec<f32> = win.clone().into_data().try_to_vec::<f32>().expect("data");
    let at = |i: usize, j: usize, ch: usize| values[((i * w) + j) * c + ch];
    assert_eq!(v[(ws * ws) * c], at(0, 4, 0));
    assert_eq!(v[(ws * ws + ws) * c + 2], at(1, 4, 2));
    let back: Vec<f32> = window_reverse(win, ws, b, h, w)
        .into_data()
        .try_to_vec::<f32>()
        .expect("data");
    assert_eq!(back, values);
    // The cyclic shift and its inverse.
    let rolled: Vec<f32> = x
        .clone()
        .roll(&[-2i64, -2], &[1usize, 2])
        .roll(&[2i64, 2], &[1usize, 2])
        .into_data()
        .try_to_vec::<f32>()
        .expect("data");
    assert_eq!(rolled, values);

    // Shift mask: after rolling by −s, a token at row i wrapped around iff i ≥ H − s (same for
    // columns); two tokens of a window may attend each other iff they wrapped alike.
    let s = ws / 2;
    let mask = shift_mask(h, w, ws, s);
    let n = ws * ws;
    let (nh, nw) = (h / ws, w / ws);
    assert_eq!(mask.len(), nh * nw * n * n);
    let mut blocked = 0;
    for wi in 0..nh {
        for wj in 0..nw {
            for a in 0..n {
                for bb in 0..n {
                    let pos = |t: usize| (wi * ws + t / ws, wj * ws + t % ws);
                    let ((ia, ja), (ib, jb)) = (pos(a), pos(bb));
                    let same = (ia >= h - s) == (ib >= h - s) && (ja >= w - s) == (jb >= w - s);
                    let m = mask[((wi * nw + wj) * n + a) * n + bb];
                    assert_eq!(m == 0.0, same, "window ({wi},{wj}) tokens {a},{bb}");
                    blocked += usize::from(m != 0.0);
                }
            }
        }
    }
    assert!(blocked > 0);
    // Relative positions: a token with itself is the table's centre; offsets are antisymmetric.
    let idx = relative_position_index(ws);
    let centre = ((ws - 1) * (2 * ws - 1) + ws - 1) as i64;
    assert!((0..n).all(|a| idx[a * n + a] == centre));
    assert!(idx
        .iter()
        .all(|&i| i >= 0 && i < ((2 * ws - 1) * (2 * ws - 1)) as i64));
    assert_eq!(idx[1] + idx[n], 2 * centre);
}

#[test]
fn geometry_channels_measure_stretch_normal_and_curvature_of_the_coarse_map() {
    // A sheared plane x(u, v) = (1.02 u, 0.97 v + 0.05 u, 0): |∂x/∂u| = √(1.02² + 0.05²),
    // |∂x/∂v| = 0.97, cos ∠ = 0.05 / |∂x/∂u|, normal +z, no curvature. Linear, so one-sided
    // and central differences agree.
    let (p, h) = (12usize, 0.0025f32);
    let plane = Array3::from_shape_fn((3, p, p), |(c, i, j)| {
        let (u, v) = (i as f32 * h, j as f32 * h);
        [1.02 * u, 0.97 * v + 0.05 * u, 0.0][c] + 0.3
    });
    let mut mask = Array2::from_elem((p, p), true);
    mask[(5, 5)] = false; // a hole: its neighbours fall back to one-sided differences
                          // (0, 8) loses both neighbours along v: no stretch or normal there.
    mask[(0, 7)] = false;
    mask[(0, 9)] = false;
    let g = geometry_channels(plane.view(), mask.view(), h);
    assert_eq!(g.dim(), (GEOMETRY_CHANNELS, p, p));
    let lu = (1.02f32 * 1.02 + 0.05 * 0.05).sqrt();
    let expect = [
        (lu - 1.0) / STRAIN_UNIT,
        (0.97 - 1.0) / STRAIN_UNIT,
        0.05 / lu / STRAIN_UNIT,
        0.0,
        0.0,
        1.0,
    ];
    for i in 0..p {
        for j in 0..p {
            let got: Vec<f32> = (0..GEOMETRY_CHANNELS).map(|c| g[(c, i, j)]).collect();
            if !mask[(i, j)] {
                assert!(got.iter().all(|&v| v == 0.0), "({i}, {j})");
            } else if (i, j) == (0, 8) {
                assert!(got[..6].iter().all(|&v| v == 0.0), "({i}, {j}) {got:?}");
            } else {
                for c in 0..6 {
                    assert!((got[c] - expect[c]).abs() < 2e-3, "({i}, {j}) {c}: {got:?}");
                }
            }
            for c in 6..9 {
                assert!(got[c].abs() < 2e-3, "({i}, {j}) curvature {c}: {got:?}");
            }
        }
    }
    // Shortening is negative and clamped at -10 units.
    let squashed = plane.mapv(|x| x * 0.5);
    let s = geometry_channels(squashed.view(), mask.view(), h);
    assert_eq!(s[(0, 3, 3)], -10.0);

    // A cylinder of radius R = 20 mm rolled along u (an isometry): normal (sin, 0, cos) of
    // u/R, curvature vector −normal/R (1 unit), stretch along u the chord's shortening.
    let r = 0.02f32;
    let p = 16usize;
    let cyl = Array3::from_shape_fn((3, p, p), |(c, i, j)| {
        let (u, v) = (i as f32 * h, j as f32 * h);
        [r * (u / r).sin(), v, r * (u / r).cos()][c]
    });
    let full = Array2::from_elem((p, p), true);
    let g = geometry_channels(cyl.view(), full.view(), h);
    let chord = ((h / r).sin() / (h / r) - 1.0) / STRAIN_UNIT;
    for i in 4..p - 4 {
        for j in 4..p - 4 {
            let t = i as f32 * h / r;
            let n = [t.sin(), 0.0, t.cos()];
            assert!((g[(0, i, j)] - chord).abs() < 2e-3, "{}", g[(0, i, j)]);
            assert!(g[(1, i, j)].abs() < 1e-3 && g[(2, i, j)].abs() < 1e-3);
            for c in 0..3 {
                assert!((g[(3 + c, i, j)] - n[c]).abs() < 1e-4, "normal {c}");
                let k = -n[c] / r / CURVATURE_UNIT;
                assert!(
                    (g[(6 + c, i, j)] - k).abs() < 0.03,
                    "curvature {c}: {}",
                    g[(6 + c, i, j)]
                );
            }
        }
    }

    // A slit (column 5 off the mask) with the cloth beyond it 1 cm away: no stencil reaches
    // across it, so the flat pixels beside it have no curvature.
    let p = 12usize; // the plane's size
    let mut slit = Array2::from_elem((p, p), true);
    for i in 0..p {
        slit[(i, 5)] = false;
    }
    let torn = Array3::from_shape_fn((3, p, p), |(c, i, j)| {
        plane[(c, i, j)] + if c == 2 && j > 5 { 0.01 } else { 0.0 }
    });
    let g = geometry_channels(torn.view(), slit.view(), h);
    for i in 0..p {
        for j in [2, 3, 4, 6, 7, 8] {
            for c in 6..9 {
                assert!(
                    g[(c, i, j)].abs() < 2e-3,
                    "({i}, {j}) {c}: {}",
                    g[(c, i, j)]
                );
            }
        }
    }

    // In the network's input they come after the initialisation, before the mask, zero off it.
    let g = geometry_channels(plane.view(), mask.view(), h);
    let p = 12usize;
    let input = patch_input(
        plane.view(),
        Some(plane.view()),
        mask.view(),
        0.01,
        0.001,
        Some(g.view()),
        None,
    )
    .expect("masked pixels");
    assert_eq!(input.len(), (7 + GEOMETRY_CHANNELS) * p * p);
    assert_eq!(
        &input[6 * p * p..15 * p * p],
        g.as_slice().expect("standard layout")
    );
    assert_eq!(input[15 * p * p + 5 * p + 5], 0.0);
    assert_eq!(input[15 * p * p], 1.0);
    let without =
        patch_input(plane.view(), None, mask.view(), 0.01, 0.001, None, None).expect("masked");
    assert_eq!(without.len(), 4 * p * p);
}

#[test]
fn a_model_saved_before_the_geometry_input_loads_without_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let device = default_device().expect("device");
    let cfg = tiny_config();
    save_model(dir.path(), &cfg, &cfg.model.init(&device)).expect("save");
    // Drop the field, as in config.json files written before it existed.
    drop_model_field(dir.path(), "geometry_input");
    let isr = Isr::load(dir.path()).expect("load");
    assert!(!isr.cfg.model.geometry());
    assert_eq!(isr.cfg.model.in_channels(), 7);
}

#[test]
fn pixel_unshuffle_gathers_blocks_in_pytorch_order_and_shuffle_inverts_it() {
    let device = default_device().expect("device");
    let (b, c, h, w, s) = (2, 3, 4, 6, 2);
    let values: Vec<f32> = (0..b * c * h * w).map(|i| i as f32).collect();
    let x = Tensor::<4>::from_data(TensorData::new(values.clone(), [b, c, h, w]), &device);
    let u = pixel_unshuffle(x, s);
    let (ho, wo) = (h / s, w / s);
    assert_eq!(u.dims(), [b, c * s * s, ho, wo]);
    let v: Vec<f32> = u.clone().into_data().try_to_vec::<f32>().expect("data");
    for n in 0..b {
        for ch in 0..c {
            for (i, j) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                for (y, x) in [(0, 0), (1, 2), (0, 1)] {
                    let out = ((n * c * s * s + ch * s * s + i * s + j) * ho + y) * wo + x;
                    let inp = ((n * c + ch) * h + s * y + i) * w + s * x + j;
                    assert_eq!(
                        v[out], values[inp],
                        "n {n} c {ch} block ({i}, {j}) at ({y}, {x})"
                    );
                }
            }
        }
    }
    let back: Vec<f32> = pixel_shuffle(u, s)
        .into_data()
        .try_to_vec::<f32>()
        .expect("data");
    assert_eq!(back, values);
}

#[test]
fn an_unshuffled_network_keeps_the_full_resolution_and_checks_its_patch_size() {
    let device = default_device().expect("device");
    let cfg = tiny_model().with_unshuffle(Some(2));
    assert_eq!(cfg.patch_multiple(), 8);
    let net = cfg.init(&device);
    let x = Tensor::<4>::random(
        [2, cfg.in_channels(), 16, 16],
        burn::tensor::Distribution::Normal(0.0, 1.0),
        &device,
    );
    assert_eq!(net.forward(x).dims(), [2, 3, 16, 16]);
    assert!(cfg.clone().with_unshuffle(Some(0)).check().is_err());

    // A model saved without the field is not unshuffled; a patch that is not a multiple of
    // window × factor is refused with the file named.
    let dir = tempfile::tempdir().expect("tempdir");
    let mut tc = tiny_config().with_patch(16);
    tc.model = cfg.clone();
    save_model(dir.path(), &tc, &net).expect("save");
    assert_eq!(
        Isr::load(dir.path())
            .expect("load")
            .cfg
            .model
            .unshuffle_factor(),
        2
    );
    edit_config(dir.path(), |json| json["patch"] = serde_json::json!(12));
    let err = Isr::load(dir.path())
        .err()
        .expect("patch 12 refused")
        .to_string();
    assert!(
        err.contains("config.json") && err.contains("multiple of 8"),
        "{err}"
    );
    let plain = tempfile::tempdir().expect("tempdir");
    let tc = tiny_config();
    save_model(plain.path(), &tc, &tc.model.init(&device)).expect("save");
    drop_model_field(plain.path(), "unshuffle");
    assert_eq!(
        Isr::load(plain.path())
            .expect("load")
            .cfg
            .model
            .unshuffle_factor(),
        1
    );
}

#[test]
fn forward_shapes_and_the_loss_matches_the_reference_differences() {
    let device = default_device().expect("device");
    for (init, geometry) in [
        (true, None),
        (false, None),
        (true, Some(true)),
        (false, Some(true)),
    ] {
        let cfg = tiny_model()
            .with_init_input(init)
            .with_geometry_input(geometry);
        assert_eq!(
            cfg.in_channels(),
            4 + 3 * usize::from(init) + GEOMETRY_CHANNELS * usize::from(geometry.is_some())
        );
        let net = cfg.init(&device);
        let x = Tensor::<4>::ones([3, cfg.in_channels(), 16, 16], &device);
        let y = net.forward(x);
        assert_eq!(y.dims(), [3, 3, 16, 16]);
        let v: Vec<f32> = y.into_data().try_to_vec::<f32>().expect("data");
        assert!(v.iter().all(|x| x.is_finite()));
    }
    // isr_loss's gradient term against msr::gradients::gradient_l1 (pixel spacing 1).
    let p = 12;
    let mut mask = Array2::from_elem((p, p), true);
    for i in 0..p {
        for j in 0..p {
            if i + j < 5 || (i > 8 && j > 9) {
                mask[(i, j)] = false;
            }
        }
    }
    let a = Array3::from_shape_fn((3, p, p), |(c, i, j)| {
        ((c * 7 + i * 3 + j * j) as f32 * 0.37).sin()
    });
    let b = Array3::from_shape_fn((3, p, p), |(c, i, j)| ((c + i * j) as f32 * 0.21).cos());
    let masked = |x: &Array3<f32>| {
        Array3::from_shape_fn(
            x.dim(),
            |(c, i, j)| if mask[(i, j)] { x[(c, i, j)] } else { 0.0 },
        )
    };
    let (a, b) = (masked(&a), masked(&b));
    let gm = gradient_mask(&mask);
    let t = |x: &Array3<f32>| {
        Tensor::<4>::from_data(
            TensorData::new(x.iter().copied().collect(), [1, 3, p, p]),
            &device,
        )
    };
    let m1: Vec<f32> = mask.iter().map(|&m| f32::from(u8::from(m))).collect();
    let g1: Vec<f32> = gm.iter().map(|&m| f32::from(u8::from(m))).collect();
    let batch = Batch {
        inputs: t(&a),
        targets: t(&b),
        mask: Tensor::from_data(TensorData::new(m1.clone(), [1, 1, p, p]), &device),
        grad_mask: Tensor::from_data(TensorData::new(g1.clone(), [1, 1, p - 2, p - 2]), &device),
        mask_values: 3.0 * m1.iter().sum::<f32>(),
        grad_values: 6.0 * g1.iter().sum::<f32>(),
    };
    let (total, dist, cons) = isr_loss(t(&a), &batch, 1.0, 10.0);
    let reference = gradient_l1(&a, &b, &mask, 1.0);
    assert!(
        (cons as f32 - reference).abs() < 1e-5,
        "{cons} vs {reference}"
    );
    let l1: f32 = a
        .indexed_iter()
        .filter(|((_, i, j), _)| mask[(*i, *j)])
        .map(|((c, i, j), v)| (v - b[(c, i, j)]).abs())
        .sum::<f32>()
        / (3.0 * m1.iter().sum::<f32>());
    assert!((dist as f32 - l1).abs() < 1e-5);
    let total = total.into_scalar::<f32>();
    assert!((total - (l1 + 10.0 * reference)).abs() < 1e-4);
}

#[test]
fn training_lowers_the_loss_resumes_and_the_saved_model_loads_identically() {
    let seqs = vec![IsrSequence::load(&dataset(), None, FINE_M, 0.5, 1.0).expect("load")];
    assert_eq!(seqs[0].frames.len(), 8);
    let out = tempfile::tempdir().expect("tmp");
    let model = out.path().join("isr");
    let cfg = tiny_config();
    // Stop after 25 steps, then resume to the end.
    let s1 = train(&cfg, &seqs, &model, |p| {
        if p.step == 25 {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    })
    .expect("train");
    assert!(s1.interrupted);
    assert!(!model.join("model.bpk").exists());
    let mut first_step = None;
    let s2 = train(&cfg, &seqs, &model, |p| {
        first_step.get_or_insert(p.step);
        ControlFlow::Continue(())
    })
    .expect("resume");
    assert_eq!(first_step, Some(26));
    assert!(!s2.interrupted);
    let log = std::fs::read_to_string(model.join("log.csv")).expect("log");
    assert_eq!(log.matches("step,").count(), 1, "{log}");
    // Columns: step, lr, loss, position, gradient, coarse_loss, init_loss, seconds. The
    // network starts as the identity (the coarse map: loss = coarse_loss) and must end well
    // below it.
    let rows: Vec<Vec<f64>> = log
        .lines()
        .skip(1)
        .map(|l| l.split(',').filter_map(|v| v.parse().ok()).collect())
        .collect();
    assert!(
        rows.len() >= 2 && rows.iter().all(|r| r.len() == 8),
        "{log}"
    );
    let ratio =
        |r: &[Vec<f64>]| r.iter().map(|r| r[2]).sum::<f64>() / r.iter().map(|r| r[5]).sum::<f64>();
    assert!((ratio(&rows[..1]) - 1.0).abs() < 0.05, "{log}");
    assert!(
        ratio(&rows[rows.len() - 8..]) < 0.96,
        "loss did not fall below the coarse map's: {log}"
    );
    // Another configuration in the same directory is refused; the finished model too.
    let err = train(&cfg.clone().with_beta(1.0), &seqs, &model, |_| {
        ControlFlow::Continue(())
    });
    assert!(err.is_err());

    // save → load: identical outputs.
    let device = default_device().expect("device");
    let net = cfg.model.init(&device);
    let dir = out.path().join("random");
    save_model(&dir, &cfg, &net).expect("save");
    let loaded = Isr::load(&dir).expect("load");
    let fresh = Isr::from_net(cfg.clone(), net, device);
    let n = cfg.model.in_channels() * 16 * 16 * 2;
    let input: Vec<f32> = (0..n)
        .map(|i| ((i * 13 % 29) as f32 - 14.0) * 0.1)
        .collect();
    let a = loaded.run(input.clone(), 2).expect("run");
    let b = fresh.run(input, 2).expect("run");
    assert_eq!(a, b);
}

#[test]
fn super_resolution_runs_on_a_sequence_and_ignores_where_the_garment_is() {
    let seq = IsrSequence::load(&dataset(), None, FINE_M, 0.5, 0.0).expect("load");
    let device = default_device().expect("device");
    let cfg = tiny_config();
    let isr = Isr::from_net(cfg.clone(), cfg.model.init(&device), device);
    let e = evaluate(&seq, &isr, false, |_, _| ControlFlow::Continue(())).expect("evaluate");
    let tf = evaluate(&seq, &isr, true, |_, _| ControlFlow::Continue(())).expect("evaluate");
    assert_eq!(tf.frames.len(), 8);
    // The first frame starts from the coarse map either way.
    assert_eq!(tf.frames[0].sr_mm, e.frames[0].sr_mm);
    assert_eq!(e.frames.len(), 8);
    assert!(e
        .frames
        .iter()
        .all(|f| f.sr_mm.is_finite() && f.upsampled_mm.is_finite()));
    // Jitter from the third frame on; normal angles on every frame.
    assert!(e.frames[..2].iter().all(|f| f.jitter_mm.is_none()));
    for f in &e.frames[2..] {
        let j = f.jitter_mm.expect("jitter from the third frame");
        assert!(j.sr.is_finite() && j.gt > 0.0 && j.sr_err >= 0.0 && j.phong_err >= 0.0);
    }
    assert!(e
        .frames
        .iter()
        .all(|f| f.sr_normal_deg.is_finite() && f.phong_normal_deg >= 0.0));
    // The upsampled coarse mesh is close to the fine simulation (a few mm, not metres).
    assert!(e.mean_upsampled_mm() < 20.0, "{}", e.mean_upsampled_mm());

    // Moving M_int by 1 m moves the fine mesh by 1 m and changes nothing else.
    let shift = Vector3::new(1.0, -0.5, 2.0);
    let mut a = SuperResolver::new(&isr, &seq.coarse_mesh, &seq.fine_mesh, &[]).expect("sr");
    let mut b = SuperResolver::new(&isr, &seq.coarse_mesh, &seq.fine_mesh, &[]).expect("sr");
    for int in seq.int_x.iter().take(2) {
        let moved: Vec<Vector3<f64>> = int.iter().map(|p| p + shift).collect();
        let fa = a.frame(int).expect("frame");
        let fb = b.frame(&moved).expect("frame");
        assert_eq!(fa.len(), seq.fine_mesh.num_vertices());
        let worst = fa
            .iter()
            .zip(&fb)
            .map(|(p, q)| (q - p - shift).norm())
            .fold(0.0, f64::max);
        assert!(worst < 1e-5, "moved output differs by {worst} m");
    }
}

#[test]
fn a_fabric_conditioned_network_reads_the_data_sets_fabric_and_answers_to_it() {
    let seqs = vec![IsrSequence::load(&dataset(), None, FINE_M, 0.5, 1.0).expect("load")];
    let conditions = seqs[0]
        .conditions
        .clone()
        .expect("the data set records its fabric");
    let silk = clothsr::garment::Fabric::preset("silk").expect("silk");
    assert!(!conditions.is_empty());
    for c in &conditions {
        assert_eq!(c.bending_n_m, silk.bending_n_m);
        // 40 mm over 10 mm, as meshed.
        assert!((c.ratio - 4.0).abs() < 0.6, "{}", c.ratio);
    }
    let mut cfg = tiny_config().with_steps(30);
    cfg.model = tiny_model().with_condition_input(Some(true));
    assert_eq!(cfg.model.in_channels(), tiny_model().in_channels() + 4);
    let out = tempfile::tempdir().expect("tmp");
    let dir = out.path().join("isr");
    train(&cfg, &seqs, &dir, |_| ControlFlow::Continue(())).expect("train");
    let isr = Isr::load(&dir).expect("load");
    let seq = &seqs[0];
    // The network needs one condition per panel.
    assert!(SuperResolver::new(&isr, &seq.coarse_mesh, &seq.fine_mesh, &[]).is_err());
    let run = |c: &[clothsr::msr::Condition]| {
        let mut sr =
            SuperResolver::new(&isr, &seq.coarse_mesh, &seq.fine_mesh, c).expect("resolver");
        sr.frame(&seq.int_x[3]).expect("frame")
    };
    let stiffer: Vec<_> = conditions
        .iter()
        .map(|c| clothsr::msr::Condition {
            bending_n_m: c.bending_n_m * 100.0,
            ..*c
        })
        .collect();
    let (a, b) = (run(&conditions), run(&stiffer));
    let moved = a
        .iter()
        .zip(&b)
        .map(|(p, q)| (p - q).norm())
        .fold(0.0, f64::max);
    assert!(moved > 1e-7, "the fabric does not reach the network");
    assert_eq!(a, run(&conditions));
}
