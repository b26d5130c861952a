//! Regression: the USD bridge's first use from several threads at once deadlocked (a thread
//! waited for Python's one-time set-up while holding the GIL that the set-up needed back).
//! Found when two pipeline tests ran in parallel; a DCC host calling clothsr from worker
//! threads would hang the same way. This file is its own process, so Python starts here.

use std::path::Path;
use std::sync::mpsc;
use std::time::Duration;

#[test]
fn first_bridge_use_from_four_threads_at_once_does_not_deadlock() {
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/sheet_table.usda");
    let (tx, rx) = mpsc::channel();
    for _ in 0..4 {
        let (tx, sample) = (tx.clone(), sample.clone());
        std::thread::spawn(move || {
            let r = clothsr::io::usd::inspect_usd(&sample).map(|s| s.meshes.len());
            let _ = tx.send(r);
        });
    }
    for _ in 0..4 {
        // A deadlock shows as a timeout; the stuck threads die with the process.
        let meshes = rx
            .recv_timeout(Duration::from_secs(120))
            .expect("a thread hung: the bridge deadlocked")
            .expect("inspect");
        assert!(meshes > 0);
    }
}
