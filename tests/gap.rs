//! Integration tests of the sim-to-real gap diagnosis (issue 7): loaders, identification on
//! synthetic rig data with known parameters, diagnosis and the blind test.

use ddct::gap::identify::{identify, IdentifyOptions};
use ddct::gap::synth::{rig_dataset, RigExperiment, SensorNoise};
use ddct::model::params::Params;
use ddct::model::powertrain::Nominal;

fn perturbed(p: &Params) -> Params {
    let mut q = *p;
    q.clutch.x_isp0_mm = 3.8;
    q.clutch.x_isp1_mm_per_c = -1.5e-3;
    q.clutch.x_isp2_mm_per_c2 = 0.0;
    let t = &mut q.thermal5;
    t.alpha1_per_s *= 1.3;
    t.alpha2_per_s *= 0.7;
    t.alpha3_k_per_j *= 1.2;
    t.alpha4_per_s *= 0.8;
    t.alpha5_per_s *= 1.25;
    t.alpha6_per_s *= 0.8;
    t.alpha7_k_per_j *= 0.85;
    t.alpha8_per_s *= 1.3;
    t.alpha9_k_per_j *= 0.8;
    q
}

#[test]
fn identify_recovers_known_parameters() {
    let truth = Params::default();
    let step = 0.005;
    let t0 = std::time::Instant::now();
    let train = rig_dataset(
        "train",
        &truth,
        Nominal,
        &RigExperiment::identification(40, 900.0),
        SensorNoise::default(),
        11,
        step,
    )
    .unwrap();
    let val = rig_dataset(
        "validate",
        &truth,
        Nominal,
        &RigExperiment::validation(20, 300.0),
        SensorNoise::default(),
        12,
        step,
    )
    .unwrap();
    eprintln!("synthetic data {:?}", t0.elapsed());
    let t0 = std::time::Instant::now();
    let init = perturbed(&truth);
    let id = identify(&[train], &[val], &init, &IdentifyOptions::default()).unwrap();
    eprintln!("identify {:?}", t0.elapsed());
    for n in &id.notes {
        eprintln!("{n}");
    }
    // The final estimates: step 2 (convective terms) and step 5 (joint).
    let finals: Vec<_> = id
        .estimates
        .iter()
        .filter(|e| e.step.starts_with('2') || e.step.starts_with('5'))
        .collect();
    assert_eq!(
        finals.len(),
        12,
        "α2, α8 from the cooling phase; 7 thermal + 3 torque jointly"
    );
    let mut inside = 0;
    for e in &finals {
        let t = ddct::gap::keys::get(&truth, &e.key).unwrap();
        let init_err = (e.initial - t).abs();
        let err = (e.value - t).abs();
        let ok = e.ci95.0 <= t && t <= e.ci95.1;
        inside += usize::from(ok);
        eprintln!(
            "{:28} initial {:>11.4e} fitted {:>11.4e} [{:>11.4e}, {:>11.4e}] truth {:>11.4e} {}",
            e.key,
            e.initial,
            e.value,
            e.ci95.0,
            e.ci95.1,
            t,
            if ok { "inside" } else { "outside" }
        );
        assert!(e.identifiable, "{} not identifiable", e.key);
        // Every parameter lands inside its interval or, where the interval is narrower than the
        // replay's discretisation bias, within 6 % of the truth; and at least 3 times closer to
        // the truth than its perturbed start.
        let half = 0.5 * (e.ci95.1 - e.ci95.0);
        assert!(
            err <= half.max(0.06 * t.abs()),
            "{}: {} vs truth {t}",
            e.key,
            e.value
        );
        assert!(
            err * 3.0 <= init_err || err <= 1e-3 * t.abs(),
            "{}: did not improve",
            e.key
        );
    }
    // Most intervals cover the truth (the rest miss by discretisation bias of a few %).
    assert!(inside >= 8, "only {inside} of 12 intervals cover the truth");
    // Validation fit % at the sensor-noise level on the other profile.
    for f in &id.validation {
        eprintln!(
            "{} {} {} fit {:.2} % rmse {:.3}",
            f.file, f.output, f.mode, f.fit_pct, f.rmse
        );
        if f.output.starts_with("T_c") || f.output.starts_with("th_") {
            assert!(f.fit_pct > 97.0, "{} {}: {}", f.output, f.mode, f.fit_pct);
        }
    }
}
