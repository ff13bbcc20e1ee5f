//! Integration tests of the physics core (issue 4): golden values of (13), inverse round trip,
//! properties of the characteristic, thermal relaxation and energy book-keeping, driveline
//! stick/slip.

use ddct::model::{clutch, Params};

/// DESIGN.md §4 golden values: (x_to mm, slip rad/s, θ °C, torque N·m).
const GOLDEN: [(f64, f64, f64, f64); 7] = [
    (4.8, 50.0, 25.0, 37.184),
    (4.8, 50.0, 240.0, 85.495),
    (5.5, 1.0, 140.0, 120.797),
    (6.0, 200.0, 25.0, 136.361),
    (3.9, 50.0, 240.0, 26.251),
    (7.0, 0.3, 25.0, 285.359),
    (7.0, 0.02, 25.0, 272.742),
];

#[test]
fn golden_values_of_13() {
    let p = Params::default().clutch;
    for (x, w, th, gold) in GOLDEN {
        let t = clutch::torque(&p, x, w, th);
        let rel = ((t - gold) / gold).abs();
        println!("T({x}, {w}, {th}) = {t:.6} (golden {gold}, rel {rel:.2e})");
        assert!(rel < 1e-4, "T({x},{w},{th}) = {t}, golden {gold}");
    }
}

#[test]
fn inverse_round_trip_over_grid() {
    let p = Params::default().clutch;
    let mut n = 0;
    for &th in &[-20.0, 25.0, 80.0, 140.0, 200.0, 240.0, 300.0] {
        for &w in &[0.0, 1e-4, 0.02, 0.3, 1.0, 10.0, 50.0, 200.0, 600.0] {
            let tmax = clutch::max_torque(&p, w, th);
            for k in 1..=40 {
                let t = tmax * k as f64 / 41.0;
                let inv = clutch::invert(&p, t, w, th).unwrap();
                assert!(!inv.saturated);
                let wt = if w == 0.0 { 0.0 } else { w };
                let back = if wt == 0.0 {
                    clutch::capacity(&p, inv.x_to_mm, th)
                } else {
                    clutch::torque(&p, inv.x_to_mm, wt, th)
                };
                assert!(
                    (back - t).abs() < 1e-6 * t,
                    "th={th} w={w} t={t} back={back}"
                );
                n += 1;
            }
        }
    }
    assert_eq!(n, 7 * 9 * 40);
}

#[test]
fn inverse_position_exact_to_1e6_mm() {
    // Forward then inverse: the position comes back to 1e-6 mm inside the compression range.
    let p = Params::default().clutch;
    for &th in &[25.0, 140.0, 240.0] {
        let x0 = clutch::x_isp(&p, th);
        for k in 1..100 {
            let x = x0 + (p.x_to_max_mm - x0) * k as f64 / 100.0;
            for &w in &[0.5, 50.0] {
                let t = clutch::torque(&p, x, w, th);
                let inv = clutch::invert(&p, t, w, th).unwrap();
                assert!((inv.x_to_mm - x).abs() < 1e-6, "x={x} back={}", inv.x_to_mm);
            }
        }
    }
}

#[test]
fn inverse_zero_and_saturation() {
    let p = Params::default().clutch;
    for &th in &[25.0, 240.0] {
        let inv = clutch::invert(&p, 0.0, 30.0, th).unwrap();
        assert_eq!(inv.x_to_mm, clutch::x_isp(&p, th));
        assert!(!inv.saturated);
        let tmax = clutch::max_torque(&p, 30.0, th);
        let inv = clutch::invert(&p, 1.01 * tmax, 30.0, th).unwrap();
        assert_eq!(inv.x_to_mm, p.x_to_max_mm);
        assert!(inv.saturated);
        // The sign of the request does not matter: the inverse works on magnitudes.
        let a = clutch::invert(&p, 50.0, 30.0, th).unwrap();
        let b = clutch::invert(&p, -50.0, -30.0, th).unwrap();
        assert_eq!(a, b);
    }
}
