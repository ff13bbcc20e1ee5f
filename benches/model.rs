//! Benchmark of the physics core against a python/numpy peer run by the same bench
//! (`cargo bench --bench model`): cost of torque() (13), invert() and one full plant derivative
//! evaluation, reported in ns/call and as python/rust ratios, and the torque per element over
//! 200 000 points by `clutch_batch::torque_batch` against numpy's vectorised torque. The peer is
//! `benches/model_peer.py`, run with `$DDCT_PYTHON`, else `.venv/bin/python`, else `python3`;
//! both sides evaluate the same points and the bench checks that their values agree.

use ddct::model::clutch;
use ddct::model::clutch_batch;
use ddct::model::driveline::{self, GearShaft};
use ddct::model::gear::Gear;
use ddct::model::powertrain::{Inputs, Powertrain, State};
use ddct::model::thermal::Thermal5State;
use ddct::model::{ClutchParams, Params};
use std::hint::black_box;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

/// Best-of-5 mean time per call (ns).
fn time_ns(n: usize, mut f: impl FnMut()) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        let t0 = Instant::now();
        for _ in 0..n {
            f();
        }
        best = best.min(t0.elapsed().as_nanos() as f64 / n as f64);
    }
    best
}

fn peer(root: &Path) -> Option<serde_json::Value> {
    let script = root.join("benches/model_peer.py");
    let venv = root.join(".venv/bin/python");
    let python = std::env::var("DDCT_PYTHON").ok().unwrap_or_else(|| {
        if venv.exists() {
            venv.display().to_string()
        } else {
            "python3".into()
        }
    });
    let out = Command::new(&python).arg(&script).arg("20000").output();
    match out {
        Ok(o) if o.status.success() => serde_json::from_slice(&o.stdout).ok(),
        Ok(o) => {
            eprintln!(
                "python peer failed ({python}): {}",
                String::from_utf8_lossy(&o.stderr)
                    .lines()
                    .last()
                    .unwrap_or("")
            );
            None
        }
        Err(e) => {
            eprintln!("python peer not runnable ({python}): {e}");
            None
        }
    }
}

/// Largest difference of the batch torque from the scalar torque() over the points, relative
/// (absolute below 1 N·m); infinite when one is NaN and the other not.
fn batch_difference(c: &ClutchParams, xs: &[f64], ws: &[f64], ths: &[f64]) -> f64 {
    let mut out = vec![0.0; xs.len()];
    if clutch_batch::torque_batch(c, xs, ws, ths, &mut out).is_err() {
        return f64::INFINITY;
    }
    (0..xs.len())
        .map(|i| {
            let (a, b) = (out[i], clutch::torque(c, xs[i], ws[i], ths[i]));
            match (a.is_nan(), b.is_nan()) {
                (true, true) => 0.0,
                (false, false) => (a - b).abs() / b.abs().max(1.0),
                _ => f64::INFINITY,
            }
        })
        .fold(0.0, f64::max)
}

/// Points of the per-element rows.
const POINTS: usize = 200_000;

/// Per-element cost over many points (numpy's vectorised best case): the batch function over
/// structure-of-arrays slices, its baseline code, the batch on two threads and the scalar
/// function in a loop (ns per point), and the batch's largest difference from the scalar.
fn per_element(c: &ClutchParams) -> (f64, f64, f64, f64, f64) {
    let m = POINTS;
    let pts: Vec<(f64, f64, f64)> = (0..m)
        .map(|i| {
            let a = (i as f64 * 0.618_033_988_7).fract();
            let b = (i as f64 * 0.414_213_562_3).fract();
            let d = (i as f64 * 0.732_050_807_5).fract();
            (3.0 + 4.2 * a, -200.0 + 400.0 * b, 20.0 + 230.0 * d)
        })
        .collect();
    let xs: Vec<f64> = pts.iter().map(|q| q.0).collect();
    let ws: Vec<f64> = pts.iter().map(|q| q.1).collect();
    let ths: Vec<f64> = pts.iter().map(|q| q.2).collect();
    let mut out = vec![0.0; m];
    let batch_ns = time_ns(10, || {
        clutch_batch::torque_batch(c, &xs, &ws, &ths, black_box(&mut out)).unwrap();
    }) / m as f64;
    let portable_ns = time_ns(10, || {
        clutch_batch::torque_batch_portable(c, &xs, &ws, &ths, black_box(&mut out)).unwrap();
    }) / m as f64;
    let scalar_loop_ns = time_ns(3, || {
        let mut acc = 0.0;
        for &(x, w, th) in &pts {
            acc += clutch::torque(c, x, w, th);
        }
        black_box(acc);
    }) / m as f64;
    let two_threads_ns = time_ns(10, || {
        let h = m / 2;
        let (lo, hi) = out.split_at_mut(h);
        std::thread::scope(|sc| {
            let first =
                sc.spawn(|| clutch_batch::torque_batch(c, &xs[..h], &ws[..h], &ths[..h], lo));
            clutch_batch::torque_batch(c, &xs[h..], &ws[h..], &ths[h..], hi).unwrap();
            first.join().unwrap().unwrap();
        });
        black_box(&out);
    }) / m as f64;
    let diff = batch_difference(c, &xs, &ws, &ths);
    (batch_ns, portable_ns, two_threads_ns, scalar_loop_ns, diff)
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let p = Params::load(root.join("config/params.toml")).expect("config/params.toml");
    let c = p.clutch;

    let torque_ns = time_ns(2_000_000, || {
        black_box(clutch::torque(
            &c,
            black_box(5.5),
            black_box(37.0),
            black_box(140.0),
        ));
    });
    let inverse_ns = time_ns(2_000_000, || {
        black_box(clutch::invert(&c, black_box(120.0), black_box(37.0), black_box(140.0)).ok());
    });

    let pt = Powertrain::new(p);
    let k1 = driveline::overall_ratio(&p.driveline, Gear::G1).unwrap();
    let mut s = State::at_rest(0.0, 25.0);
    s.w_f = 250.0;
    s.w_c1 = 250.0;
    s.w_c2 = 120.0;
    s.w_out = 250.0 / k1;
    s.x1_mm = 6.5;
    s.x2_mm = 4.6;
    s.engine_torque_nm = 80.0;
    s.lock1 = true;
    s.gear_odd = GearShaft::engaged(Gear::G1);
    s.thermal = Thermal5State {
        pp1: 90.0,
        pp2: 80.0,
        c1: 120.0,
        c2: 110.0,
        cd: 95.0,
    };
    let u = Inputs {
        x1_ref_mm: 6.5,
        x2_ref_mm: 4.7,
        gear_odd_req: Gear::G1,
        pedal: 0.4,
        grade: 0.05,
        theta_h_c: 40.0,
        ..Default::default()
    };
    let derivative_ns = time_ns(500_000, || {
        black_box(pt.derivative(black_box(&s), black_box(&u)));
    });
    let step_ns = time_ns(100_000, || {
        let mut x = s;
        black_box(pt.step(&mut x, black_box(&u), 1e-3));
    });
    let (torque_vec_ns, portable_ns, two_threads_ns, scalar_loop_ns, batch_diff) = per_element(&c);
    let batch_agrees = batch_diff <= 1e-12;
    let m = POINTS;

    let o = pt.outputs(&s, &u);
    println!("ddct model bench (release build; best of 5)");
    println!(
        "{:<34} {:>12} {:>12} {:>10}",
        "function", "rust ns", "python ns", "py/rust"
    );
    let rows = [
        ("torque() (13)", torque_ns, "torque_ns"),
        ("invert() of (13)", inverse_ns, "inverse_ns"),
        (
            "plant derivative (full powertrain)",
            derivative_ns,
            "derivative_ns",
        ),
        (
            "torque per element, vectorised",
            torque_vec_ns,
            "torque_vec_ns",
        ),
    ];
    // Beside the rows: no peer of their own (numpy's vectorised figure is the row above's).
    let extra = [
        ("  batch, baseline SSE2 code", portable_ns),
        ("  batch, 2 threads", two_threads_ns),
        ("  scalar torque() in a loop", scalar_loop_ns),
    ];
    let py = peer(root);
    for (name, rust, key) in rows {
        match py.as_ref().and_then(|v| v[key].as_f64()) {
            Some(pyns) => println!("{name:<34} {rust:>12.1} {pyns:>12.1} {:>10.1}", pyns / rust),
            None => println!("{name:<34} {rust:>12.1} {:>12} {:>10}", "n/a", "n/a"),
        }
    }
    for (name, rust) in extra {
        println!("{name:<34} {rust:>12.1}");
    }
    println!(
        "{:<34} {step_ns:>12.1}",
        "powertrain step (RK4 1 ms + events)"
    );
    println!(
        "batch agreement: batch = scalar: {batch_agrees} ({m} points, largest relative difference \
         {batch_diff:.1e})"
    );
    if let Some(v) = &py {
        let chk = &v["check"];
        let t_rs = clutch::torque(&c, 4.8, 50.0, 240.0);
        let x_rs = clutch::invert(&c, 120.0, 37.0, 140.0).unwrap().x_to_mm;
        let agree =
            |a: f64, b: Option<f64>| b.is_some_and(|b| (a - b).abs() <= 1e-6 * a.abs().max(1.0));
        println!(
            "peer agreement: torque {} inverse {} dω_f/dt {} T_fc1 {} (vectorised = scalar: {}, \
             batch = scalar: {batch_agrees})",
            agree(t_rs, chk["torque_4.8_50_240"].as_f64()),
            agree(x_rs, chk["inverse_120_37_140"].as_f64()),
            agree(o.acc[0], chk["derivative_w_f"].as_f64()),
            agree(o.t_fc1_nm, chk["derivative_t_fc1"].as_f64()),
            chk["vec_matches_scalar"]
        );
    }
}
