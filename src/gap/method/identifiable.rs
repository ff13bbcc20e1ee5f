//! Identifiability of the recalibration (issue 45, item 2): a recalibrated parameter is moved,
//! and reported as moved, only where the training records determine it.
//!
//! The criterion is the records' sensitivity to the parameter: the change of the fit's χ² that
//! a move of the parameter by its plausible half-width (±[`PLAUSIBLE_REL`] of nominal) makes,
//! Δχ² = Σ ((ŷ(p + δ) − ŷ(p)) / σ)² over the fit samples of every checked channel, σ each
//! record's noise floor: the Fisher information of the parameter under noise at the floor. (Not
//! scaled by an effective sample size from the residuals' autocorrelation: where a model error
//! dominates the residuals — an actuator dead time against the lag τ — their autocorrelation
//! says nothing of the noise's, and the scaling would call the lag undetermined on records that
//! show it step by step.) Below [`MIN_DELTA_CHI2`] = 3.84, the 95 %
//! point of χ² with one degree of freedom, a profile-likelihood interval of the parameter would
//! reach past its whole plausible range: the records do not determine it. Such a parameter
//! stays nominal (the move the fit made is noise or a trade with another parameter), is listed
//! as undetermined with the operating range that would determine it, and is not recalibrated
//! again by the class fits or the out-of-range refit.
//!
//! Example: μ_s of (4) weighs on the friction radius (6) only at low slip,
//! μ_s·R̄ + (μ_d − μ_s)·Q(ω) with Q(ω) → R̄ within a few rad/s; on a rig record at 150 rad/s of
//! slip no sample sees it.

use crate::gap::eval::predict;
use crate::gap::method::context::{self, File};
use crate::gap::method::select::{plausible, PLAUSIBLE_REL};
use crate::gap::model::candidate::{Channel, Model};
use crate::gap::model::keys::ParamKey;
use crate::model::clutch;
use crate::model::params::{ClutchParams, Params};

/// Δχ² below which the records do not determine a parameter (χ²₁, 95 %).
pub const MIN_DELTA_CHI2: f64 = 3.84;

/// A recalibration parameter the records do not determine.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Undetermined {
    pub key: ParamKey,
    /// The value the recalibration had moved it to before it was set back to nominal.
    pub fitted: f64,
    pub nominal: f64,
    /// Δχ² of a move by its plausible half-width ([`MIN_DELTA_CHI2`] needed).
    pub delta_chi2: f64,
    /// Where records would determine it.
    pub determined_by: String,
}

/// The Δχ² on the fit samples of `files` over `chans` of moving `key` of `model` by its
/// plausible half-width (up, or down where up leaves the plausible range).
pub fn delta_chi2(
    model: &Model,
    nominal: &Params,
    key: ParamKey,
    files: &[File],
    chans: &[Channel],
) -> f64 {
    Probe {
        nominal,
        files,
        chans,
    }
    .delta(&standardized(model, files, chans), model, key)
}

/// What a move is judged on: the nominal parameters and the records' channels.
struct Probe<'a> {
    nominal: &'a Params,
    files: &'a [File],
    chans: &'a [Channel],
}

impl Probe<'_> {
    /// [`delta_chi2`] with the standardized residuals `base` of `model` given.
    fn delta(&self, base: &[f64], model: &Model, key: ParamKey) -> f64 {
        let v = key.get(&model.p);
        let step = PLAUSIBLE_REL * key.get(self.nominal).abs();
        let (_, hi) = plausible(key, self.nominal);
        let mut moved = *model;
        key.set(
            &mut moved.p,
            if v + step <= hi { v + step } else { v - step },
        );
        if moved.p.clutch.validate().is_err() {
            key.set(&mut moved.p, v - step);
        }
        base.iter()
            .zip(&standardized(&moved, self.files, self.chans))
            .map(|(a, b)| (a - b) * (a - b))
            .filter(|d| d.is_finite())
            .sum()
    }
}

/// The standardized residual r/σ of `model` at every fit sample of `files` over `chans`, in a
/// fixed order (NaN where the prediction is not finite).
fn standardized(model: &Model, files: &[File], chans: &[Channel]) -> Vec<f64> {
    let preds = context::predictions(model, files, chans, true, false);
    let mut r = Vec::new();
    for (file, pr) in files.iter().zip(&preds) {
        for &c in chans {
            let y = &pr.y[c.index()];
            for &k in file.fit.get(c) {
                let e = predict::measured(&file.m, c, k) - y.get(k).copied().unwrap_or(f64::NAN);
                r.push(e / file.sigma[c.index()]);
            }
        }
    }
    r
}

/// The parameters of `keys` the records do not determine at `model`, each with its Δχ².
pub fn undetermined(
    model: &Model,
    nominal: &Params,
    keys: &[ParamKey],
    files: &[File],
    chans: &[Channel],
) -> Vec<Undetermined> {
    let base = standardized(model, files, chans);
    let probe = Probe {
        nominal,
        files,
        chans,
    };
    keys.iter()
        .filter_map(|&key| {
            let d = probe.delta(&base, model, key);
            (d < MIN_DELTA_CHI2).then(|| Undetermined {
                key,
                fitted: key.get(&model.p),
                nominal: key.get(nominal),
                delta_chi2: d,
                determined_by: determined_by(key, &nominal.clutch),
            })
        })
        .collect()
}

/// Where records would determine `key`: the operating range in which its term of the model
/// acts.
pub fn determined_by(key: ParamKey, clutch: &ClutchParams) -> String {
    use ParamKey::*;
    match key {
        MuS => format!(
            "torque measured at slip below {:.0} rad/s, where μ_s carries at least 5 % of the \
             friction radius (6): launches from standstill, or a rig profile through low slip",
            static_share_limit(clutch, 0.05)
        ),
        C4 => "torque measured while a clutch slips (the dynamic friction level of (5))".into(),
        XIsp0 => "torque measured through engagements, x_to crossing the kiss point (9)".into(),
        XIsp1 | XIsp2 => {
            "engagements at disk temperatures tens of °C apart (the kiss point's temperature \
             terms of (9))"
                .into()
        }
        Alpha2 => {
            "plate temperatures with the clutch open, cooling toward the housing (16a)".into()
        }
        Alpha3 => "plate temperatures while the clutch slips, heated by friction (16a)".into(),
        Alpha8 => "the central-disk temperature with a clutch open (16e)".into(),
        Alpha9 => "the central-disk temperature while a clutch slips (16e)".into(),
        TauS => {
            "position requests logged with the positions, through steps (the actuator lag)".into()
        }
        _ => format!("records where {key} acts"),
    }
}

/// The slip (rad/s) above which μ_s carries less than `share` of the friction radius
/// R_μ = μ_s·R̄ + (μ_d − μ_s)·Q(ω) of (6), the weight of μ_s being 1 − Q(ω)/R̄ (bisection;
/// Q rises with ω).
fn static_share_limit(p: &ClutchParams, share: f64) -> f64 {
    let mean = 0.5 * (p.r1_m + p.r2_m);
    let weight = |w: f64| 1.0 - clutch::slip_shape(p, w) / mean;
    let (mut lo, mut hi) = (0.0, 1.0);
    while weight(hi) > share && hi < 1e4 {
        hi *= 2.0;
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if weight(mid) > share {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_static_level_fades_within_the_slip_the_limit_names() {
        // Q(ω)/R̄ = mean over the facing of tanh(γρω)^(1/3)·ρ/R̄: at the limit the weight of μ_s
        // is 5 %, below it more, far above it nothing.
        let p = Params::default().clutch;
        let w = static_share_limit(&p, 0.05);
        let mean = 0.5 * (p.r1_m + p.r2_m);
        let weight = |w: f64| 1.0 - clutch::slip_shape(&p, w) / mean;
        assert!((weight(w) - 0.05).abs() < 1e-6, "{}", weight(w));
        assert!(weight(0.5 * w) > 0.05);
        assert!(weight(150.0) < 1e-3, "{}", weight(150.0));
        // The nominal γ = 2 s/m over radii of 0.075–0.115 m: tanh(γρω)^(1/3) ≥ 0.95 needs
        // γρω ≥ atanh(0.857) ≈ 1.28, so the limit lies between 1.28/(2·0.115) ≈ 5.6 and
        // 1.28/(2·0.075) ≈ 8.6 rad/s.
        assert!((4.0..12.0).contains(&w), "{w}");
    }
}
