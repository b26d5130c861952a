//! The simulator's benchmark alone, without the rest of clothsr:
//!
//! ```text
//! cargo run --release -p clothsr-sim --example bench -- [SIZES] [STEPS] [fast|converged] [self|noself] [SOLVER] [WARM_UP]
//! ```
//!
//! with SOLVER `auto` (the default), `jacobi`, `two-level:AGGREGATE:REFACTOR_ABOVE` or
//! `cholesky:REFACTOR_ABOVE`, and WARM_UP the untimed steps first (default: those that bring the
//! sheet onto the sphere; 0 times its free fall); e.g. `-- 3k,40k 15 fast`; prints each size's time per step and where it went.
//! `RUST_LOG=clothsr_sim=trace` shows each Newton iteration.

use clothsr_sim::bench::{
    parse_vertices, phase_columns, phase_header, sheet_on_sphere, time_steps, WARM_UP_STEPS,
};
use clothsr_sim::LinearSolver;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .init();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let sizes = args.first().map_or("3k,40k", String::as_str);
    let steps: usize = args.get(1).map_or(Ok(15), |s| s.parse())?;
    let converged = args.get(2).is_some_and(|m| m == "converged");
    let self_collision = args.get(3).is_some_and(|s| s == "self");
    let solver = match args.get(4).map(|s| s.split(':').collect::<Vec<_>>()) {
        None => LinearSolver::Auto,
        Some(s) => match s.as_slice() {
            ["auto"] => LinearSolver::Auto,
            ["jacobi"] => LinearSolver::JacobiPcg,
            ["two-level", a, r] => LinearSolver::TwoLevelPcg {
                aggregate: a.parse()?,
                refactor_above: r.parse()?,
            },
            ["cholesky", r] => LinearSolver::CholeskyPcg {
                refactor_above: r.parse()?,
            },
            _ => return Err(format!("unknown solver {s:?}").into()),
        },
    };
    println!(
        "{:>7} {:>9} {:>8} {:>8}{}",
        "verts",
        "ms/step",
        "newton",
        "cg/nt",
        phase_header()
    );
    for s in sizes.split(',') {
        let verts = parse_vertices(s).ok_or_else(|| format!("bad size '{s}' (e.g. 3k, 40000)"))?;
        let mut sim = sheet_on_sphere(verts, |p| {
            p.newton_exact = converged;
            p.collision.self_collision = self_collision;
            p.linear_solver = solver;
        })?;
        let warm_up: usize = args.get(5).map_or(Ok(WARM_UP_STEPS), |s| s.parse())?;
        let t = time_steps(&mut sim, warm_up, steps)?;
        println!(
            "{:>7} {:>9.2} {:>8.2} {:>8.1}{}",
            t.vertices,
            t.ms_per_step,
            t.newton_per_step,
            t.cg_per_newton,
            phase_columns(&t.phases)
        );
    }
    Ok(())
}
