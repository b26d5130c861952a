//! `clothsr::corrector`: the GNN corrector on a tiny data set — training lowers the loss,
//! save → load gives identical outputs, batching graphs changes nothing, a zero input gives a
//! finite correction, window rollout training and the rollout evaluation run beside the real
//! coarse simulator.

mod common;

use clothsr::corrector::data::{vectors, Sequence};
use clothsr::corrector::fused::{FusedInputs, FusedNet};
use clothsr::corrector::graph::MeshGraph;
use clothsr::corrector::inference::{features, Corrector, WEIGHTS_FILE};
use clothsr::corrector::model::{Decoder, GraphTensors, DEFAULT_TENSION_RAMP};
use clothsr::corrector::rollout::{
    evaluate, evaluate_from, interleaved_errors, jitter_directions, sequence_distance_mm,
    HorizonErrors,
};
use clothsr::corrector::training::{
    fit_normalisation, save_model, train, TrainSet, ValidationSet, VALIDATION_LOG,
};
use clothsr::corrector::{CorrectorConfig, TrainingConfig};
use clothsr::data::{coarse_simulation, Variation};
use clothsr::dataset::{generate, Options};
use clothsr::garment::Fabric;
use clothsr::nn::common::{default_device, init_network};
use clothsr::pipeline::calibrate::{score, sim_alone_errors, CalibrationSet};
use clothsr::pipeline::CoarseCalibration;
use clothsr::scene::samples::flat_sheet;
use clothsr::scene::Scene;
use nalgebra::Vector3;
use std::ops::ControlFlow;

fn scene() -> Scene {
    common::sheet_over_ball("silk", 0.17)
}

/// A 4-frame data set at 40 mm / 15 mm (coarse ~80 vertices) of `variation`.
fn make_dataset(variation: Variation) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("tmp");
    let opts = Options {
        coarse_edge_m: 0.04,
        fine_edge_m: 0.015,
        frames: 4,
        dress: false,
        self_collision: false,
        variation,
        fast: true,
        fine_mode: clothsr::sim::step::SolverMode::Data,
        match_contact_thickness: true,
        source: None,
    };
    generate(&scene(), "test", &opts, dir.path(), |_| {}).expect("generate");
    dir
}

/// The tests' data set ([`make_dataset`] of the scene as it is), made once per test binary.
fn dataset() -> std::path::PathBuf {
    static DIR: std::sync::OnceLock<tempfile::TempDir> = std::sync::OnceLock::new();
    DIR.get_or_init(|| make_dataset(Variation::default()))
        .path()
        .to_path_buf()
}

fn load(frames: Option<std::ops::RangeInclusive<usize>>) -> Sequence {
    let sim = coarse_simulation(&scene(), &dataset(), 1).expect("coarse simulation");
    Sequence::load(&dataset(), frames, &sim).expect("load")
}

/// The tests' data set as the one training set, with a fresh coarse simulator for phase 2.
fn sets() -> Vec<TrainSet> {
    let dir = dataset();
    let sim = coarse_simulation(&scene(), &dir, 1).expect("coarse simulation");
    let t0 = sim.state.t_s;
    let seq = Sequence::load(&dir, None, &sim).expect("load");
    vec![TrainSet {
        seq,
        sim: Some((sim, t0)),
    }]
}

/// A progress callback that stops training after phase-2 window `window`.
fn stop_in_phase_2_at(
    window: usize,
) -> impl FnMut(&clothsr::corrector::training::Progress) -> ControlFlow<()> {
    move |p| {
        if p.phase == 2 && p.step == window {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }
}

fn tiny_config() -> TrainingConfig {
    TrainingConfig::new(CorrectorConfig::new().with_latent(16).with_steps(2))
        .with_steps(60)
        .with_batch(2)
        .with_lr_start(3e-3)
        .with_lr_end(1e-3)
        .with_checkpoint_every(25)
}

/// A training stopped in phase 1, then in phase 2, and resumed from its checkpoint each time
/// (training noise on, so that every random draw counts) ends with the network of one that
/// never stopped: the two correct a coarse step alike (bit for bit here; the bound leaves
/// room for sums threaded in another order).
#[test]
fn a_stopped_training_resumes_to_the_uninterrupted_network() {
    let seq = load(None);
    let out = tempfile::tempdir().expect("tmp");
    let cfg = tiny_config()
        .with_noise_ratio(0.5)
        .with_rollout_iters(6)
        .with_window(3);
    let straight = out.path().join("straight");
    train(&cfg, &mut sets(), &[], &straight, |_| {
        ControlFlow::Continue(())
    })
    .expect("straight");
    // Stopped in phase 1, then in phase 2, each part with a fresh coarse simulator, as a new
    // process would have.
    let stopped = out.path().join("stopped");
    for (phase, step) in [(1, 37), (2, 3)] {
        let part = train(&cfg, &mut sets(), &[], &stopped, |p| {
            if (p.phase, p.step) == (phase, step) {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        })
        .expect("a part");
        assert!(part.interrupted);
    }
    train(&cfg, &mut sets(), &[], &stopped, |_| {
        ControlFlow::Continue(())
    })
    .expect("resumed");
    let sim = coarse_simulation(&scene(), &dataset(), 1).expect("coarse simulation");
    let corrected = |dir: &std::path::Path| {
        let c = Corrector::load(dir, &seq.mesh).expect("load");
        let (k, st) = (2, &seq.steps[2]);
        let mut state = clothsr::sim::SimState {
            x: vectors(&st.coarse_x),
            v: vectors(&st.coarse_v),
            t_s: seq.step_time_s(k),
        };
        let before = state.x.clone();
        c.correct(&vectors(&seq.steps[k - 1].int_v), &mut state, &sim)
            .expect("correct");
        (before, state.x)
    };
    let ((before, a), (_, b)) = (corrected(&straight), corrected(&stopped));
    let moved = dist(&a, &before);
    let apart = dist(&a, &b);
    eprintln!("correction {moved:e} m, resumed vs straight {apart:e} m");
    assert!(moved > 0.0, "the corrector corrects");
    assert!(
        apart <= 1e-6 * moved,
        "resumed {apart:e} m from straight (correction {moved:e} m)"
    );
}

#[test]
fn training_lowers_the_loss_and_the_saved_model_loads() {
    let seq = load(None);
    assert_eq!(seq.steps.len(), 4 * seq.manifest.steps_per_frame);
    let out = tempfile::tempdir().expect("tmp");
    let model = out.path().join("model");
    let mut sets = vec![TrainSet {
        seq: seq.clone(),
        sim: None,
    }];
    let mut losses = Vec::new();
    let cfg = TrainingConfig::new(CorrectorConfig::new().with_latent(32).with_steps(2))
        .with_steps(300)
        .with_batch(2)
        .with_lr_start(3e-3)
        .with_lr_end(1e-3)
        .with_noise_ratio(0.0);
    let summary = train(&cfg, &mut sets, &[], &model, |p| {
        losses.push(p.loss);
        ControlFlow::Continue(())
    })
    .expect("train");
    assert_eq!(losses.len(), 300);
    let first: f64 = losses[..10].iter().sum::<f64>() / 10.0;
    let last: f64 = losses[290..].iter().sum::<f64>() / 10.0;
    assert!(last < 0.95 * first, "loss {first} → {last}");
    assert_eq!(summary.noise_std_m, 0.0);
    for f in ["config.json", "normalisation.json", "model.bpk", "log.csv"] {
        assert!(model.join(f).exists(), "{f}");
    }
    assert!(!model.join("checkpoint").exists());
    let log = std::fs::read_to_string(model.join("log.csv")).expect("log");
    assert!(log.starts_with("phase,step,lr,loss,seconds") && log.lines().count() >= 3);

    // Training again into a finished model directory is refused, naming the file.
    let e =
        train(&cfg, &mut sets, &[], &model, |_| ControlFlow::Continue(())).expect_err("finished");
    assert!(e.to_string().contains("model.bpk"), "{e}");

    // The loaded corrector moves M_c towards M_int on average over the training steps.
    let c = Corrector::load(&model, &seq.mesh).expect("load");
    let sim = coarse_simulation(&scene(), &dataset(), 1).expect("coarse simulation");
    let (mut before, mut after) = (0.0, 0.0);
    for (k, st) in seq.steps.iter().enumerate().skip(1) {
        let mut state = clothsr::sim::SimState {
            x: vectors(&st.coarse_x),
            v: vectors(&st.coarse_v),
            t_s: seq.step_time_s(k),
        };
        let gt = vectors(&st.int_x);
        before += dist(&state.x, &gt);
        c.correct(&vectors(&seq.steps[k - 1].int_v), &mut state, &sim)
            .expect("correct");
        after += dist(&state.x, &gt);
    }
    assert!(
        after < before,
        "corrector error {after} vs uncorrected {before}"
    );
}

fn dist(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (p - q).norm()).sum()
}

/// Every decoder, each without and with attention.
fn every_network_kind() -> impl Iterator<Item = (bool, Decoder)> {
    let kinds = [Decoder::Node, Decoder::Gated];
    [false, true]
        .into_iter()
        .flat_map(move |a| kinds.map(|d| (a, d)))
}

#[test]
fn save_load_is_exact_batching_is_transparent_and_zero_input_is_finite() {
    let seq = load(Some(1..=1));
    let sets = vec![TrainSet {
        seq: seq.clone(),
        sim: None,
    }];
    let norm = fit_normalisation(&sets);
    for (attention, decoder) in every_network_kind() {
        let cfg = TrainingConfig::new(
            CorrectorConfig::new()
                .with_latent(16)
                .with_steps(3)
                .with_attention(attention)
                .with_decoder(decoder)
                .with_tension_ramp(0.0),
        );
        assert_eq!(cfg.model.tension_ramp(), None);
        let default = cfg
            .model
            .clone()
            .with_tension_ramp(CorrectorConfig::new().tension_ramp);
        assert_eq!(
            default.tension_ramp(),
            decoder.is_gated().then_some(DEFAULT_TENSION_RAMP)
        );
        let device = default_device().expect("device");
        // Seeded: the checks below on what the gate does hold for most random weights, not all.
        let net = init_network(&device, Some(11), || cfg.model.init(&device));
        let dir = tempfile::tempdir().expect("tmp");
        save_model(dir.path(), &cfg, &norm, &net).expect("save");
        let loaded = Corrector::load(dir.path(), &seq.mesh).expect("load");
        let st = &seq.steps[3];
        let (x, v) = (vectors(&st.coarse_x), vectors(&st.coarse_v));
        let dv = vectors(st.dv.as_deref().expect("Δq after the first step"));
        // Direct forward pass of the in-memory network.
        let (nodes, edges) = features(&seq.graph, &x, &v, &dv, &st.body, &norm);
        let mut step_change: Vec<f32> = st.dv.clone().expect("Δq");
        norm.targets.apply(&mut step_change);
        let g = GraphTensors::of(
            &seq.graph,
            nodes.clone(),
            edges.clone(),
            step_change.clone(),
            &device,
        );
        let direct: Vec<f32> = net
            .forward(&g)
            .into_data()
            .try_to_vec::<f32>()
            .expect("vec");
        assert_eq!(direct.len(), 3 * seq.graph.num_nodes);
        // The edges cut into parts run in parallel give the same function, to the order of
        // the sums at each receiver; inference cuts them into one part per rayon thread.
        for parts in [2, 3, 7] {
            let split: Vec<f32> = net
                .forward_in_parts(&g, parts)
                .into_data()
                .try_to_vec::<f32>()
                .expect("vec");
            for (k, (a, b)) in direct.iter().zip(&split).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-5 * (1.0 + a.abs()),
                    "{parts} parts, {k}: {a} vs {b} (attention {attention}, {decoder:?})"
                );
            }
        }
        // At inference on the CPU the loaded model runs the fused forward pass, the in-memory
        // network's on burn: the same function to the order of the sums, and each the same
        // bits as the in-memory network run the same way (the loaded weights are exact).
        assert!(loaded.is_fused());
        let parts = rayon::current_num_threads();
        let inference: Vec<f32> = net
            .forward_in_parts(&g, parts)
            .into_data()
            .try_to_vec::<f32>()
            .expect("vec");
        let fused = FusedNet::of(&net).forward(
            FusedInputs {
                nodes: &nodes,
                edges: &edges,
                senders: &seq.graph.senders,
                receivers: &seq.graph.receivers,
                step_change: &step_change,
                tension: None,
            },
            parts,
        );
        // The loaded model owns its weights: the folder may go while it runs (burn's own
        // file loader read them lazily and panicked here).
        std::fs::remove_file(dir.path().join(WEIGHTS_FILE)).expect("remove the weights");
        let mut on_burn = Corrector::new(
            net.clone(),
            norm.clone(),
            cfg.clone(),
            &seq.mesh,
            dir.path(),
            &device,
        );
        on_burn.use_burn();
        assert!(!on_burn.is_fused());
        for (c, out) in [(&loaded, &fused), (&on_burn, &inference)] {
            let mut expect = out.clone();
            norm.targets.invert(&mut expect);
            let p = c.predict(&x, &v, &dv, &st.body).expect("predict");
            for (a, b) in p.iter().flat_map(|p| p.iter().copied()).zip(&expect) {
                assert_eq!(a as f32, *b, "attention {attention}, {decoder:?}");
            }
        }
        for (k, (a, b)) in direct.iter().zip(&fused).enumerate() {
            assert!(
                (a - b).abs() <= 1e-5 * (1.0 + a.abs()),
                "fused, {k}: {a} vs {b} (attention {attention}, {decoder:?})"
            );
        }
        // Two graphs in one batch give each graph's own output.
        let n = seq.graph.num_nodes as u32;
        let senders: Vec<u32> = seq
            .graph
            .senders
            .iter()
            .copied()
            .chain(seq.graph.senders.iter().map(|s| s + n))
            .collect();
        let receivers: Vec<u32> = seq
            .graph
            .receivers
            .iter()
            .copied()
            .chain(seq.graph.receivers.iter().map(|s| s + n))
            .collect();
        let both = GraphTensors::new(
            [nodes.clone(), nodes].concat(),
            [edges.clone(), edges].concat(),
            &senders,
            &receivers,
            [step_change.clone(), step_change].concat(),
            &device,
        );
        let batched: Vec<f32> = net
            .forward(&both)
            .into_data()
            .try_to_vec::<f32>()
            .expect("vec");
        for (k, b) in batched.iter().enumerate() {
            let a = direct[k % direct.len()];
            assert!((a - b).abs() <= 1e-5 * (1.0 + a.abs()), "{k}: {a} vs {b}");
        }
        // A state the corrector would push past 20 m/s is refused and left as it was.
        let mut fast = clothsr::sim::SimState {
            x: x.clone(),
            v: vec![Vector3::new(0.0, -30.0, 0.0); x.len()],
            t_s: 0.0,
        };
        let before = fast.clone();
        let sim = coarse_simulation(&scene(), &dataset(), 1).expect("coarse simulation");
        let e = loaded
            .correct(&before.v, &mut fast, &sim)
            .expect_err("too fast");
        assert!(e.to_string().contains("diverged"), "{e}");
        assert_eq!(fast, before);
        // Smoothing at inference applies the mesh graph's low-pass filter to the correction.
        let mut smoothed_cfg = cfg.clone();
        smoothed_cfg.model.smoothing = 3;
        let smooth_dir = tempfile::tempdir().expect("tmp");
        save_model(smooth_dir.path(), &smoothed_cfg, &norm, &net).expect("save");
        let smoothed = Corrector::load(smooth_dir.path(), &seq.mesh).expect("load");
        let start_v = vec![Vector3::zeros(); x.len()];
        let state = clothsr::sim::SimState {
            x: x.clone(),
            v: v.clone(),
            t_s: 0.0,
        };
        let (mut raw, mut low) = (state.clone(), state.clone());
        loaded.correct(&start_v, &mut raw, &sim).expect("correct");
        smoothed.correct(&start_v, &mut low, &sim).expect("correct");
        let mut p: Vec<Vector3<f64>> = raw.v.iter().zip(&v).map(|(a, b)| a - b).collect();
        let before = p.clone();
        seq.graph.smooth(&mut p, 3);
        assert!(
            dist(&p, &before) > 1e-5 * dist(&before, &start_v),
            "{decoder:?}: smoothing changed nothing: {} of {}",
            dist(&p, &before),
            dist(&before, &start_v)
        );
        for ((a, b), v) in low.v.iter().zip(&p).zip(&v) {
            assert!(
                (a - v - b).norm() <= 1e-9 * (1.0 + b.norm()),
                "{decoder:?}: {a} {b}"
            );
        }
        // Away from colliders, the gated decoder takes back a share in (0, 1) of each
        // component of the step's velocity change beyond gravity, and nothing in free fall.
        if decoder == Decoder::Gated {
            let far = vec![0.0; x.len()];
            let p = loaded.predict(&x, &v, &dv, &far).expect("predict");
            for (p, d) in p.iter().zip(&dv) {
                for k in 0..3 {
                    let share = -p[k] / d[k];
                    assert!(d[k] == 0.0 || (share > 0.0 && share < 1.0), "share {share}");
                }
            }
            let zero = vec![Vector3::zeros(); x.len()];
            let p = loaded.predict(&x, &v, &zero, &far).expect("predict");
            assert!(p.iter().all(|p| *p == Vector3::zeros()), "free fall");
            // With a tension limit the same weights take back w = clamp(1 − ε̄/ramp, 0, 1)
            // times as much at each vertex, nothing where the cloth is stretched past it.
            // A take-back scale k multiplies the same share once more: k·w·p exactly.
            let with_config = |c: &TrainingConfig| {
                let dir = tempfile::tempdir().expect("tmp");
                save_model(dir.path(), c, &norm, &net).expect("save");
                Corrector::load(dir.path(), &seq.mesh).expect("load")
            };
            let mut limited = cfg.clone();
            limited.model.tension_ramp = 0.01;
            let lim = with_config(&limited);
            let mut scaled = limited.clone();
            scaled.model.take_back = 0.5;
            let half = with_config(&scaled);
            let free = loaded.predict(&x, &v, &dv, &far).expect("predict");
            let w = seq.graph.tension_weight(&x, 0.01);
            assert!(w.iter().any(|&w| w > 0.0) && w.iter().all(|w| (0.0..=1.0).contains(w)));
            for (c, k) in [(&lim, 1.0), (&half, 0.5)] {
                let held = c.predict(&x, &v, &dv, &far).expect("predict");
                for ((a, b), w) in free.iter().zip(&held).zip(&w) {
                    assert!(
                        (a * k * f64::from(*w) - b).norm() <= 1e-6 * (1.0 + a.norm()),
                        "{a} {b} {w} {k}"
                    );
                }
            }
            for bad in [0.0, 1.5, f64::NAN] {
                let mut c = limited.clone();
                c.model.take_back = bad;
                assert!(c.model.check().is_err(), "take-back {bad}");
            }
            let c = x.iter().sum::<Vector3<f64>>() / x.len() as f64;
            let stretched: Vec<Vector3<f64>> = x.iter().map(|p| c + (p - c) * 1.05).collect();
            let p = lim.predict(&stretched, &v, &dv, &far).expect("predict");
            assert!(p.iter().all(|p| *p == Vector3::zeros()), "stretched 5 %");
            // A lowest share m maps the same gate output σ to m + (1 − m)σ: at m = −1 the
            // correction is 2p + Δq (it may amplify the step's velocity change), nothing in
            // free fall still.
            let mut wide = cfg.clone();
            wide.model.share_min = -1.0;
            let two_sided = with_config(&wide);
            let q = two_sided.predict(&x, &v, &dv, &far).expect("predict");
            for ((a, b), d) in free.iter().zip(&q).zip(&dv) {
                assert!(
                    (a * 2.0 + d - b).norm() <= 1e-6 * (1.0 + a.norm() + d.norm()),
                    "{a} {b} {d}"
                );
            }
            assert!(
                q.iter()
                    .zip(&dv)
                    .any(|(q, d)| (0..3).any(|k| q[k] * d[k] > 0.0)),
                "nothing amplified"
            );
            let p = two_sided.predict(&x, &v, &zero, &far).expect("predict");
            assert!(p.iter().all(|p| *p == Vector3::zeros()), "free fall");
            for bad in [1.0, f64::NAN] {
                let mut c = wide.clone();
                c.model.share_min = bad;
                assert!(c.model.check().is_err(), "share min {bad}");
            }
        }
        // A mesh collapsed to a point at rest still gets a finite correction.
        let zeros = vec![Vector3::zeros(); x.len()];
        let p = loaded
            .predict(&zeros, &zeros, &zeros, &vec![1.0; x.len()])
            .expect("predict zeros");
        assert!(p.iter().all(|p| p.iter().all(|c| c.is_finite())));
    }
}

#[test]
fn jitter_directions_are_horizontal_unit_and_evenly_spread() {
    let down = Vector3::new(0.0, -9.81, 0.0);
    let d = jitter_directions(down, 4);
    assert_eq!(d.len(), 4);
    assert!((d[0] - Vector3::x()).norm() < 1e-12, "{:?}", d[0]);
    for v in &d {
        assert!(
            (v.norm() - 1.0).abs() < 1e-12 && v.dot(&down).abs() < 1e-12,
            "{v}"
        );
    }
    // Four directions at right angles: opposite pairs, the second a quarter turn on.
    assert!((d[0] + d[2]).norm() < 1e-12 && (d[1] + d[3]).norm() < 1e-12);
    assert!(d[0].dot(&d[1]).abs() < 1e-12);
    // Any gravity: perpendicular to it, summing to zero.
    let g = Vector3::new(1.0, -2.0, 0.5);
    let d = jitter_directions(g, 3);
    let sum: Vector3<f64> = d.iter().sum();
    assert!(sum.norm() < 1e-12 && d.iter().all(|v| v.dot(&g).abs() < 1e-12));
    assert!(jitter_directions(Vector3::zeros(), 3).is_empty());
    assert!(jitter_directions(down, 0).is_empty());
}

#[test]
fn recomputed_coarse_steps_are_the_stored_ones_unless_the_simulator_changes() {
    let stored = load(None);
    let mean_gap = |seq: &Sequence| {
        let (mut sum, mut n) = (0.0, 0);
        for (a, b) in seq.steps.iter().zip(&stored.steps).skip(1) {
            sum += dist(&vectors(&a.coarse_x), &vectors(&b.coarse_x));
            n += a.coarse_x.len() / 3;
        }
        sum / n as f64
    };
    let mut same = stored.clone();
    let mut sim = coarse_simulation(&scene(), &dataset(), 1).expect("coarse simulation");
    let t0 = sim.state.t_s;
    same.recompute_coarse(&mut sim, t0).expect("recompute");
    let mut soft = stored.clone();
    let mut sim = coarse_simulation(&scene(), &dataset(), 1).expect("coarse simulation");
    sim.sim
        .model
        .set_membrane_compression(0.05, None)
        .expect("factor");
    soft.recompute_coarse(&mut sim, t0).expect("recompute");
    let (g_same, g_soft) = (mean_gap(&same), mean_gap(&soft));
    eprintln!("recomputed M_c vs stored: same simulator {g_same:e} m, soft membrane {g_soft:e} m");
    assert!(g_same < 1e-6, "{g_same}");
    assert!(g_soft > 1e-5 && g_soft > 100.0 * g_same, "{g_soft}");
    assert!(sim.sim.model.set_membrane_compression(0.0, None).is_err());
    assert!(sim
        .sim
        .model
        .set_membrane_compression(0.1, Some(0.0))
        .is_err());
}

#[test]
fn graph_of_a_data_set_mesh_matches_its_edges() {
    let seq = load(Some(1..=1));
    let g = MeshGraph::new(&seq.mesh);
    assert_eq!(g.num_edges(), 2 * seq.mesh.edges().len());
    assert_eq!(g, seq.graph);
}

#[test]
fn rollout_training_and_evaluation_run_with_the_coarse_simulator() {
    let dir = dataset();
    let sim = coarse_simulation(&scene(), &dir, 1).expect("coarse simulation");
    let t0 = sim.state.t_s;
    let seq = Sequence::load(&dir, None, &sim).expect("load");
    // The coarse simulator has the fine one's contact thickness, below its own default.
    let dhat = seq.manifest.coarse_dhat_m.expect("matched thickness");
    assert_eq!(sim.sim.params.collision.dhat_m, dhat);
    assert!(dhat < 0.15 * seq.manifest.coarse_mean_edge_m, "{dhat}");
    let mut sets = vec![TrainSet {
        seq: seq.clone(),
        sim: Some((sim, t0)),
    }];
    let cfg = tiny_config()
        .with_noise_ratio(0.3)
        .with_steps(20)
        .with_rollout_iters(4)
        .with_window(3)
        .with_rollout_lr(1e-3);
    let out = tempfile::tempdir().expect("tmp");
    let s = train(&cfg, &mut sets, &[], out.path(), |_| {
        ControlFlow::Continue(())
    })
    .expect("train");
    assert_eq!(s.phase2_iters, 4);
    assert!(s.noise_std_m > 0.0);
    assert!(s.phase2_first_last.0.is_finite() && s.phase2_first_last.1.is_finite());

    let corrector = Corrector::load(out.path(), &seq.mesh).expect("load");
    let mut sim = coarse_simulation(&scene(), &dir, 1).expect("coarse simulation");
    let mut alone = coarse_simulation(&scene(), &dir, 1).expect("coarse simulation");
    let mut check = coarse_simulation(&scene(), &dir, 1).expect("coarse simulation");
    let e = evaluate(
        &seq,
        [&mut alone, &mut sim, &mut check],
        t0,
        &corrector,
        3,
        |_, _, _, _| {},
    )
    .expect("evaluate");
    assert_eq!(e.frame, vec![1, 2, 3]);
    for v in [
        &e.sim_alone_mm,
        &e.interleaved_mm,
        &e.not_interleaved_mm,
        &e.one_step_uncorrected_mm,
        &e.one_step_corrected_mm,
    ] {
        assert_eq!(v.len(), 3);
        assert!(v.iter().all(|x| x.is_finite() && *x >= 0.0));
    }
    // The simulator alone starts on the ground truth, so its first-frame error is small
    // (sub-millimetre) but not zero: resolutions differ.
    assert!(
        e.sim_alone_mm[0] > 0.0 && e.sim_alone_mm[0] < 5.0,
        "{:?}",
        e.sim_alone_mm
    );
    assert!(e.csv().lines().count() == 4);
    // The interleaved run alone (what training validates on) is evaluate's interleaved
    // column, bit for bit, from a fresh simulator.
    let mut fresh = coarse_simulation(&scene(), &dir, 1).expect("coarse simulation");
    let only = interleaved_errors(&seq, &mut fresh, t0, &corrector, 3)
        .expect("interleaved")
        .expect("not diverged");
    assert_eq!(only, e.interleaved_mm);
    assert!(interleaved_errors(&seq, &mut fresh, t0, &corrector, 4).is_err());
    // A corrector trained beside half the fabric's bending and no crease contacts sets its
    // coarse simulation up so; by default it leaves both as the simulator's.
    let mut trained = TrainingConfig::new(CorrectorConfig::new());
    let mut beside = coarse_simulation(&scene(), &dir, 1).expect("coarse simulation");
    trained.prepare_coarse(&mut beside).expect("default");
    assert_eq!(beside.sim.model.bending_scale(), 1.0);
    assert!(beside.sim.detector().crease_contacts);
    trained.coarse.bending = Some(0.5);
    trained.coarse.crease_contacts = Some(false);
    trained.prepare_coarse(&mut beside).expect("calibrated");
    assert_eq!(beside.sim.model.bending_scale(), 0.5);
    assert!(!beside.sim.detector().crease_contacts);
    // `clothsr calibrate` scores a coarse model by the simulation alone: the simulator's own
    // model gives evaluate's sim-alone column bit for bit; a compression-soft membrane, a
    // grip or wrinkle bending set through `CoarseCalibration::apply` changes it.
    let mut fresh = coarse_simulation(&scene(), &dir, 1).expect("coarse simulation");
    let own = sim_alone_errors(&seq, &mut fresh, t0, 3, Vector3::zeros()).expect("sim alone");
    assert_eq!(own, e.sim_alone_mm);
    let set = CalibrationSet::load(scene(), &dir, Some(3)).expect("calibration set");
    let soft = CoarseCalibration {
        compression: Some(0.05),
        friction: Some(2.0),
        wrinkle_bending: Some(1.0),
        ..CoarseCalibration::default()
    };
    let runs = std::sync::atomic::AtomicUsize::new(0);
    let shift = [Vector3::new(1e-4, 0.0, 0.0)];
    let scored = score(
        &[set],
        &[CoarseCalibration::default(), soft],
        &shift,
        || {
            runs.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        },
    )
    .expect("score");
    assert_eq!(runs.into_inner(), 4);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert_eq!(scored[0].run_means_mm[0][0], mean(&e.sim_alone_mm));
    assert_ne!(scored[0].run_means_mm[0][0], scored[0].run_means_mm[0][1]);
    assert!(
        (scored[0].pooled_mm - mean(&scored[0].run_means_mm[0])).abs() < 1e-12,
        "{:?}",
        scored[0]
    );
    assert_eq!(scored[1].calibration, soft);
    assert!(scored[1].failed.is_none() && scored[1].pooled_mm.is_finite());
    assert_ne!(scored[1].pooled_mm, scored[0].pooled_mm);
    let mut sim = coarse_simulation(&scene(), &dir, 1).expect("coarse simulation");
    soft.apply(&mut sim).expect("apply");
    assert_eq!(sim.sim.params.friction, 2.0);
    let model = &sim.sim.model;
    assert!(model.membrane_k.iter().all(|k| k.compression == 0.05));
    assert_eq!(model.wrinkle_bending().map(|w| w.gain), Some(1.0));
    assert_eq!(model.bending_scale(), 1.0);
    assert_eq!(e.strain_pct.len(), 3);
    // Interleaved and alone start from the ground truth: a percent-level strain gap after
    // one frame would be a bookkeeping error.
    let [g, a, b] = e.strain_pct[0];
    assert!(
        g.is_finite() && (a - g).abs() < 1.0 && (b - g).abs() < 1.0,
        "{g} {a} {b}"
    );
    // The rigid part |mean(x − x_gt)| never exceeds the mean distance (triangle inequality).
    assert_eq!(e.offset_mm.len(), 3);
    for (k, [oa, oi]) in e.offset_mm.iter().enumerate() {
        assert!(*oa >= 0.0 && *oa <= e.sim_alone_mm[k] + 1e-9, "{oa}");
        assert!(*oi >= 0.0 && *oi <= e.interleaved_mm[k] + 1e-9, "{oi}");
    }
    assert_eq!(
        e.csv().lines().next().map(|l| l.split(',').count()),
        Some(11)
    );

    // From the ground truth at frame 2 of the loaded sequence: the same as a sequence loaded
    // from frame 2 (fresh simulators each), numbered in the data set's frames.
    let fresh = || coarse_simulation(&scene(), &dir, 1).expect("coarse simulation");
    let (mut a, mut b, mut c) = (fresh(), fresh(), fresh());
    let spf = seq.manifest.steps_per_frame;
    let later = evaluate_from(
        &seq,
        spf,
        [&mut a, &mut b, &mut c],
        t0,
        &corrector,
        2,
        |_, _, _, _| {},
    )
    .expect("evaluate from frame 2");
    let from2 = Sequence::load(&dir, Some(2..=seq.manifest.frames_done), &fresh()).expect("load");
    let (mut a, mut b, mut c) = (fresh(), fresh(), fresh());
    let direct = evaluate(
        &from2,
        [&mut a, &mut b, &mut c],
        t0,
        &corrector,
        2,
        |_, _, _, _| {},
    )
    .expect("evaluate");
    assert_eq!(later.frame, vec![2, 3]);
    for (x, y) in [
        (&later.sim_alone_mm, &direct.sim_alone_mm),
        (&later.interleaved_mm, &direct.interleaved_mm),
        (&later.not_interleaved_mm, &direct.not_interleaved_mm),
        (&later.one_step_corrected_mm, &direct.one_step_corrected_mm),
    ] {
        assert_eq!(x, y);
    }
    let (mut a, mut b, mut c) = (fresh(), fresh(), fresh());
    assert!(evaluate_from(
        &seq,
        1,
        [&mut a, &mut b, &mut c],
        t0,
        &corrector,
        1,
        |_, _, _, _| {}
    )
    .is_err());
    // Short horizons average per frame after the start; the distance of a sequence to itself
    // is zero, to the stored M_c not.
    let h = HorizonErrors::from_runs(&[1, 2], &[e.clone(), later.clone()], 2).expect("average");
    assert!(
        (h.interleaved_mm[1] - (e.interleaved_mm[1] + later.interleaved_mm[1]) / 2.0).abs() < 1e-12
    );
    assert!(HorizonErrors::from_runs(&[1], std::slice::from_ref(&later), 3).is_err());
    assert_eq!(
        sequence_distance_mm(&seq, &seq, &[1, 3]).expect("distance"),
        vec![0.0, 0.0]
    );
    let mut moved = seq.clone();
    for st in &mut moved.steps {
        for (k, x) in st.int_x.iter_mut().enumerate() {
            if k % 3 == 1 {
                *x += 0.002;
            }
        }
    }
    for d in sequence_distance_mm(&seq, &moved, &[1, 2]).expect("distance") {
        assert!((d - 2.0).abs() < 1e-3, "{d}");
    }
    assert!(sequence_distance_mm(&seq, &moved, &[9]).is_err());

    // A scene that meshes differently is refused, naming the stored meshes.
    let mut other = scene();
    other.garments[0] = flat_sheet(
        "sheet",
        0.2,
        0.3,
        Vector3::new(0.0, 0.17, 0.0),
        Fabric::preset("silk").expect("preset"),
    );
    let err = coarse_simulation(&other, &dir, 1)
        .err()
        .expect("different mesh");
    assert!(err.to_string().contains("meshes.safetensors"), "{err}");
}

#[test]
fn an_interrupted_training_run_resumes_from_its_checkpoint() {
    let seq = load(None);
    let mut sets = vec![TrainSet { seq, sim: None }];
    let cfg = tiny_config().with_steps(40).with_checkpoint_every(10);
    let out = tempfile::tempdir().expect("tmp");
    let s = train(&cfg, &mut sets, &[], out.path(), |p| {
        if p.step == 25 {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    })
    .expect("first part");
    assert!(s.interrupted);
    assert!(!out.path().join("model.bpk").exists());
    assert!(out.path().join("checkpoint/state.json").exists());
    // Another configuration is refused, naming the config file.
    let e = train(
        &cfg.clone().with_steps(41),
        &mut sets,
        &[],
        out.path(),
        |_| ControlFlow::Continue(()),
    )
    .expect_err("other config");
    assert!(e.to_string().contains("config.json"), "{e}");
    let mut steps = Vec::new();
    let s = train(&cfg, &mut sets, &[], out.path(), |p| {
        steps.push(p.step);
        ControlFlow::Continue(())
    })
    .expect("resume");
    assert!(!s.interrupted);
    assert_eq!(steps, (26..=40).collect::<Vec<_>>());
    assert!(out.path().join("model.bpk").exists());
    assert!(!out.path().join("checkpoint").exists());
    let log = std::fs::read_to_string(out.path().join("log.csv")).expect("log");
    assert_eq!(log.matches("phase,step").count(), 1, "{log}");
    assert!(log.lines().any(|l| l.starts_with("1,40,")), "{log}");
}

#[test]
fn validation_saves_the_best_network_and_a_resumed_run_keeps_it() {
    let dir = dataset();
    let sim = coarse_simulation(&scene(), &dir, 1).expect("coarse simulation");
    let t0 = sim.state.t_s;
    let seq = Sequence::load(&dir, None, &sim).expect("load");
    let mut sets = vec![TrainSet {
        seq,
        sim: Some((sim, t0)),
    }];
    // Held out: the sheet turned and moved.
    let held = make_dataset(Variation {
        garment_offset_m: [0.01, 0.0, -0.01],
        garment_yaw_deg: 30.0,
        ..Variation::default()
    });
    let vsim = coarse_simulation(&scene(), held.path(), 1).expect("coarse simulation");
    let vseq = Sequence::load(held.path(), None, &vsim).expect("load");
    let validation = vec![ValidationSet {
        seq: vseq.clone(),
        scene: scene(),
    }];
    let cfg = tiny_config()
        .with_steps(20)
        .with_rollout_iters(6)
        .with_window(3)
        .with_rollout_lr(3e-2)
        .with_validate_every(Some(2))
        .with_validation_frames(Some(3))
        // A seed whose last validated network is not its best (asserted below).
        .with_seed(1);
    let out = tempfile::tempdir().expect("tmp");

    // Validation data without validate_every, validate_every without data, and a training
    // set as its own validation set are refused.
    let none = cfg.clone().with_validate_every(None);
    let e = train(&none, &mut sets, &validation, out.path(), |_| {
        ControlFlow::Continue(())
    })
    .expect_err("no validate_every");
    assert!(e.to_string().contains("validate_every"), "{e}");
    let e = train(&cfg, &mut sets, &[], out.path(), |_| {
        ControlFlow::Continue(())
    })
    .expect_err("no validation data");
    assert!(e.to_string().contains("validation"), "{e}");
    let own = vec![ValidationSet {
        seq: sets[0].seq.clone(),
        scene: scene(),
    }];
    let e = train(&cfg, &mut sets, &own, out.path(), |_| {
        ControlFlow::Continue(())
    })
    .expect_err("training set as validation set");
    assert!(
        e.to_string()
            .contains("both a training and a validation set"),
        "{e}"
    );

    // Stopped in phase 2 after its first validation (window 2), then resumed.
    let first = train(
        &cfg,
        &mut sets,
        &validation,
        out.path(),
        stop_in_phase_2_at(3),
    )
    .expect("first part");
    assert!(first.interrupted);
    let points = |s: &clothsr::corrector::training::Summary| -> Vec<(u8, usize)> {
        s.validations.iter().map(|v| (v.0, v.1)).collect()
    };
    assert_eq!(points(&first), vec![(1, 20), (2, 2)]);
    assert!(out.path().join("checkpoint/best.bpk").exists());
    let rest = train(&cfg, &mut sets, &validation, out.path(), |_| {
        ControlFlow::Continue(())
    })
    .expect("resume");
    assert!(!rest.interrupted);
    // The resumed run does not repeat the end of phase 1, and validates the last window.
    assert_eq!(points(&rest), vec![(2, 4), (2, 6)]);
    let all: Vec<f64> = first
        .validations
        .iter()
        .chain(&rest.validations)
        .map(|v| v.2)
        .collect();
    assert!(all.iter().all(|mm| mm.is_finite() && *mm > 0.0), "{all:?}");
    let (best, _, _) = rest.validation_best.expect("a best network");
    let min = all.iter().copied().fold(f64::INFINITY, f64::min);
    // Read back from the checkpoint's JSON, whose parser (serde_json without its
    // float_roundtrip feature) may land one unit in the last place away.
    assert!(
        (best - min).abs() <= 4.0 * f64::EPSILON * min,
        "{best} {all:?}"
    );
    // Phase 2's large rate makes the later networks worse here, so a run that saved its
    // last network would fail below.
    assert!(all[3] > best, "{all:?}");
    // The log has a row per set and a pooled row per validation.
    let log = std::fs::read_to_string(out.path().join(VALIDATION_LOG)).expect("log");
    assert!(
        log.starts_with("phase,step,set,frames,interleaved_mm"),
        "{log}"
    );
    assert_eq!(log.lines().count(), 1 + 2 * 4, "{log}");
    assert_eq!(log.matches(",pooled,3,").count(), 4, "{log}");
    assert!(!out.path().join("checkpoint").exists());

    // The saved network is the best one: rolled out again it scores the best figure.
    let corrector = Corrector::load(out.path(), &vseq.mesh).expect("load");
    let mut fresh = coarse_simulation(&scene(), held.path(), 1).expect("coarse simulation");
    let vt0 = fresh.state.t_s;
    let e = interleaved_errors(&vseq, &mut fresh, vt0, &corrector, 3)
        .expect("rollout")
        .expect("not diverged");
    let mean = e.iter().sum::<f64>() / e.len() as f64;
    assert!((mean - best).abs() < 1e-9 * best, "{mean} vs {best}");

    // Fine-tuned from that network (phase 2 only): the start is validated first, with the
    // same figure, and the saved network is whichever validated best, the start included.
    let tuned = tempfile::tempdir().expect("tmp");
    let tune = cfg
        .clone()
        .with_steps(0)
        .with_rollout_iters(4)
        .with_init_from(Some(out.path().to_path_buf()));
    let s = train(&tune, &mut sets, &validation, tuned.path(), |_| {
        ControlFlow::Continue(())
    })
    .expect("fine-tune");
    assert_eq!(points(&s), vec![(1, 0), (2, 2), (2, 4)]);
    let start = s.validations[0].2;
    assert!((start - best).abs() < 1e-9 * best, "{start} vs {best}");
    let (kept, phase, _) = s.validation_best.expect("a best network");
    let min = s
        .validations
        .iter()
        .map(|v| v.2)
        .fold(f64::INFINITY, f64::min);
    assert_eq!(kept, min);
    let unchanged = max_difference(&parameters(out.path()), &parameters(tuned.path())) == 0.0;
    assert_eq!(unchanged, phase == 1, "{:?}", s.validations);
}

/// A network's float parameters, in visit order.
fn parameters(dir: &std::path::Path) -> Vec<Vec<f32>> {
    use burn::module::{Module, ModuleVisitor, Param};
    struct Collect(Vec<Vec<f32>>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, param: &Param<burn::tensor::Tensor<D>>) {
            self.0
                .push(param.val().into_data().try_to_vec::<f32>().expect("f32"));
        }
    }
    let device = default_device().expect("device");
    let (net, _, _) = clothsr::corrector::inference::load_net(dir, &device).expect("load");
    let mut c = Collect(Vec::new());
    net.visit(&mut c);
    c.0
}

fn max_difference(a: &[Vec<f32>], b: &[Vec<f32>]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .flat_map(|(a, b)| {
            assert_eq!(a.len(), b.len());
            a.iter().zip(b).map(|(x, y)| (x - y).abs())
        })
        .fold(0.0, f32::max)
}

#[test]
fn fine_tuning_starts_from_a_model_of_the_same_network_and_coarse_model() {
    let go = |cfg: &TrainingConfig, out: &std::path::Path| {
        train(cfg, &mut sets(), &[], out, |_| ControlFlow::Continue(())).expect("train")
    };
    let tmp = tempfile::tempdir().expect("tmp");
    let gated = CorrectorConfig::new()
        .with_latent(16)
        .with_steps(2)
        .with_decoder(Decoder::Gated)
        .with_take_back(0.5);
    let base = tmp.path().join("base");
    go(
        &TrainingConfig::new(gated.clone())
            .with_steps(20)
            .with_batch(2)
            .with_lr_start(3e-3)
            .with_lr_end(1e-3),
        &base,
    );
    let tune = |iters: usize| {
        TrainingConfig::new(gated.clone())
            .with_steps(0)
            .with_rollout_iters(iters)
            .with_window(3)
            .with_rollout_lr(3e-3)
            .with_checkpoint_every(10)
            .with_init_from(Some(base.clone()))
    };

    // A warm start from another network's sizes or coarse membrane is refused, naming the
    // model it would start from.
    let other = TrainingConfig::new(gated.clone().with_latent(32))
        .with_steps(0)
        .with_rollout_iters(2)
        .with_window(3)
        .with_init_from(Some(base.clone()));
    let e = train(&other, &mut sets(), &[], &tmp.path().join("x"), |_| {
        ControlFlow::Continue(())
    })
    .expect_err("other sizes");
    assert!(e.to_string().contains("config.json") && e.to_string().contains("latent 16"));
    let beside = |c: CoarseCalibration| tune(2).with_coarse(c);
    let soft = beside(CoarseCalibration {
        compression: Some(0.1),
        ..CoarseCalibration::default()
    });
    let e = train(&soft, &mut sets(), &[], &tmp.path().join("y"), |_| {
        ControlFlow::Continue(())
    })
    .expect_err("other membrane");
    assert!(e.to_string().contains("compression"), "{e}");
    let grip = beside(CoarseCalibration {
        friction: Some(1.0),
        ..CoarseCalibration::default()
    });
    let e = train(&grip, &mut sets(), &[], &tmp.path().join("z"), |_| {
        ControlFlow::Continue(())
    })
    .expect_err("other friction");
    assert!(e.to_string().contains("friction"), "{e}");

    // Two and three phase-2 windows from the base network.
    let (two, three) = (tmp.path().join("two"), tmp.path().join("three"));
    go(&tune(2), &two);
    go(&tune(3), &three);
    // Training starts from the base network's statistics, not ones fitted anew.
    let norm = |d: &std::path::Path| std::fs::read(d.join("normalisation.json")).expect("norm");
    assert_eq!(norm(&two), norm(&base));
    let (p0, p2, p3) = (parameters(&base), parameters(&two), parameters(&three));
    assert!(max_difference(&p0, &p2) > 1e-5, "phase 2 moved nothing");
    assert!(max_difference(&p2, &p3) > 1e-5);
    // One window less from a fresh network is not the same: the start was the base's.
    let fresh = tmp.path().join("fresh");
    go(&tune(2).with_init_from(None), &fresh);
    assert!(max_difference(&parameters(&fresh), &p2) > 1e-3);
}

/// A triangulated k × k grid as a graph's directed edge pairs (edge 2m + 1 is edge 2m
/// reversed): `(senders, receivers)`.
fn grid_edges(k: u32) -> (Vec<u32>, Vec<u32>) {
    let (mut senders, mut receivers) = (Vec::new(), Vec::new());
    for i in 0..k {
        for j in 0..k {
            let a = i * k + j;
            let mut pair = |b: u32| {
                senders.extend([a, b]);
                receivers.extend([b, a]);
            };
            if j + 1 < k {
                pair(a + 1);
            }
            if i + 1 < k {
                pair(a + k);
            }
            if i + 1 < k && j + 1 < k {
                pair(a + k + 1);
            }
        }
    }
    (senders, receivers)
}

#[test]
fn the_fused_cpu_forward_pass_is_the_burn_networks_function() {
    use burn::module::{Module, ModuleMapper, Param};
    use burn::tensor::{Distribution, Tensor};
    use clothsr::corrector::fused::TILE;
    use clothsr::corrector::graph::{EDGE_FEATURES, NODE_FEATURES};
    use rand::{Rng, SeedableRng};
    /// Every parameter moved at random: LayerNorms' γ and β away from 1 and 0, biases from 0.
    struct Jiggle;
    impl ModuleMapper for Jiggle {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            param.map(|t| {
                let noise = t.random_like(Distribution::Uniform(-0.3, 0.3));
                t + noise
            })
        }
    }
    // 17 × 17 nodes, 1,600 directed edges: several tiles per thread's range.
    let k = 17;
    let (senders, receivers) = grid_edges(k);
    let (n, e) = ((k * k) as usize, senders.len());
    assert!(e > 4 * TILE);
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let mut normal =
        |len: usize| -> Vec<f32> { (0..len).map(|_| rng.random_range(-1.5..1.5)).collect() };
    let mut nodes = normal(n * NODE_FEATURES);
    // Body proximities across the gated decoder's contact ramp (in the network's units).
    for (i, f) in nodes.chunks_exact_mut(NODE_FEATURES).enumerate() {
        f[clothsr::corrector::graph::BODY_COLUMN] = (i % 7) as f32 / 6.0;
    }
    let edges = normal(e * EDGE_FEATURES);
    let step_change = normal(3 * n);
    let tension: Vec<f32> = (0..n).map(|i| (i % 4) as f32 / 3.0).collect();
    let device = default_device().expect("device");
    for (attention, decoder) in every_network_kind() {
        for layers in [1, 2] {
            let cfg = CorrectorConfig::new()
                .with_latent(24)
                .with_hidden_layers(layers)
                .with_steps(2)
                .with_attention(attention)
                .with_decoder(decoder)
                .with_share_min(-0.2);
            let net = init_network(&device, None, || cfg.init(&device).map(&mut Jiggle));
            let fused = FusedNet::of(&net);
            // The burn network's and the fused pass's outputs on the nodes with the given edges.
            let on_burn = |edges: &[f32], senders: &[u32], receivers: &[u32]| -> Vec<f32> {
                let g = GraphTensors::new(
                    nodes.clone(),
                    edges.to_vec(),
                    senders,
                    receivers,
                    step_change.clone(),
                    &device,
                )
                .with_tension(Some(tension.clone()));
                net.forward(&g)
                    .into_data()
                    .try_to_vec::<f32>()
                    .expect("vec")
            };
            let on_fused = |edges: &[f32], senders: &[u32], receivers: &[u32], parts| {
                let inputs = FusedInputs {
                    nodes: &nodes,
                    edges,
                    senders,
                    receivers,
                    step_change: &step_change,
                    tension: Some(&tension),
                };
                fused.forward(inputs, parts)
            };
            let same = |expect: &[f32], out: &[f32], what: &str| {
                assert_eq!(out.len(), 3 * n);
                for (i, (a, b)) in expect.iter().zip(out).enumerate() {
                    assert!(
                        (a - b).abs() <= 2e-5 * (1.0 + a.abs()),
                        "{what}, {i}: {a} vs {b} (attention {attention}, {decoder:?}, \
                         {layers} hidden layers)"
                    );
                }
            };
            let direct = on_burn(&edges, &senders, &receivers);
            let scale = direct.iter().fold(0.0f32, |m, x| m.max(x.abs()));
            assert!(scale > 0.1, "{decoder:?}: a network that says nothing");
            for parts in [1, 2, 3, 7] {
                let out = on_fused(&edges, &senders, &receivers, parts);
                same(&direct, &out, &format!("{parts} parts"));
            }
            // A graph without edges: its nodes get no messages (burn's sums are zero).
            if !attention {
                same(
                    &on_burn(&[], &[], &[]),
                    &on_fused(&[], &[], &[], 2),
                    "no edges",
                );
            }
        }
    }
}
