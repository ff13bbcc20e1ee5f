//! Named access to the model parameters the identification and the recalibration re-fit, by
//! their `table.key` names in `config/params.toml` (e.g. `clutch.x_isp1_mm_per_c`).

use crate::model::params::Params;

/// The parameters that can be fitted, with their unit and a typical magnitude (the solver scale).
pub const FITTABLE: &[(&str, &str, f64)] = &[
    ("clutch.x_isp0_mm", "mm", 1.0),
    ("clutch.x_isp1_mm_per_c", "mm/°C", 1e-3),
    ("clutch.x_isp2_mm_per_c2", "mm/°C²", 1e-6),
    ("clutch.x_to_max_mm", "mm", 1.0),
    ("clutch.c4", "-", 0.01),
    ("clutch.mu_s", "-", 0.01),
    ("thermal5.alpha1_per_s", "1/s", 1e-3),
    ("thermal5.alpha2_per_s", "1/s", 1e-3),
    ("thermal5.alpha3_k_per_j", "K/J", 1e-4),
    ("thermal5.alpha4_per_s", "1/s", 1e-3),
    ("thermal5.alpha5_per_s", "1/s", 1e-3),
    ("thermal5.alpha6_per_s", "1/s", 1e-3),
    ("thermal5.alpha7_k_per_j", "K/J", 1e-4),
    ("thermal5.alpha8_per_s", "1/s", 1e-3),
    ("thermal5.alpha9_k_per_j", "K/J", 1e-4),
    ("actuator.tau_s", "s", 1e-2),
];

fn slot<'a>(p: &'a mut Params, key: &str) -> Option<&'a mut f64> {
    let c = &mut p.clutch;
    let t = &mut p.thermal5;
    Some(match key {
        "clutch.x_isp0_mm" => &mut c.x_isp0_mm,
        "clutch.x_isp1_mm_per_c" => &mut c.x_isp1_mm_per_c,
        "clutch.x_isp2_mm_per_c2" => &mut c.x_isp2_mm_per_c2,
        "clutch.x_to_max_mm" => &mut c.x_to_max_mm,
        "clutch.mu_s" => &mut c.mu_s,
        "clutch.c4" => &mut c.c4,
        "clutch.lambda" => &mut c.lambda,
        "thermal5.alpha1_per_s" => &mut t.alpha1_per_s,
        "thermal5.alpha2_per_s" => &mut t.alpha2_per_s,
        "thermal5.alpha3_k_per_j" => &mut t.alpha3_k_per_j,
        "thermal5.alpha4_per_s" => &mut t.alpha4_per_s,
        "thermal5.alpha5_per_s" => &mut t.alpha5_per_s,
        "thermal5.alpha6_per_s" => &mut t.alpha6_per_s,
        "thermal5.alpha7_k_per_j" => &mut t.alpha7_k_per_j,
        "thermal5.alpha8_per_s" => &mut t.alpha8_per_s,
        "thermal5.alpha9_k_per_j" => &mut t.alpha9_k_per_j,
        "actuator.tau_s" => &mut p.actuator.tau_s,
        _ => return None,
    })
}

/// Value of a named parameter.
pub fn get(p: &Params, key: &str) -> Option<f64> {
    let mut q = *p;
    slot(&mut q, key).map(|v| *v)
}

/// Sets a named parameter; false for an unknown name.
pub fn set(p: &mut Params, key: &str, value: f64) -> bool {
    match slot(p, key) {
        Some(v) => {
            *v = value;
            true
        }
        None => false,
    }
}

/// Unit of a fittable parameter.
pub fn unit(key: &str) -> &'static str {
    FITTABLE
        .iter()
        .find(|(k, _, _)| *k == key)
        .map(|(_, u, _)| *u)
        .unwrap_or("")
}

/// Solver scale of a fittable parameter.
pub fn scale(key: &str) -> f64 {
    FITTABLE
        .iter()
        .find(|(k, _, _)| *k == key)
        .map(|(_, _, s)| *s)
        .unwrap_or(1.0)
}

/// Allowed range of a named parameter from the parameter file's specification.
pub fn range(key: &str) -> Option<(f64, f64)> {
    use crate::model::params::{ActuatorParams, ClutchParams, ThermalParams5};
    let (table, name) = key.split_once('.')?;
    let specs = match table {
        "clutch" => ClutchParams::SPECS,
        "thermal5" => ThermalParams5::SPECS,
        "actuator" => ActuatorParams::SPECS,
        _ => return None,
    };
    specs.iter().find(|s| s.key == name).map(|s| (s.min, s.max))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_fittable_key_round_trips() {
        let mut p = Params::default();
        for (k, _, _) in FITTABLE {
            let v = get(&p, k).unwrap();
            assert!(set(&mut p, k, v * 2.0 + 1e-9), "{k}");
            assert_eq!(get(&p, k).unwrap(), v * 2.0 + 1e-9);
            assert!(range(k).is_some(), "{k}");
        }
        assert!(get(&p, "clutch.nope").is_none());
        assert!(!set(&mut p, "nope", 1.0));
        assert_eq!(
            get(&Params::default(), "clutch.x_isp1_mm_per_c"),
            Some(-2.5e-3)
        );
    }
}
