//! A scored trial as the summary reads it: the part of a [`super::TrialResult`] that
//! [`super::summarize`] and [`super::render_text`] need, read back from a report's JSON. Every
//! summary goes through it — a run's own trials as well as trials run apart and merged
//! (`ddct gap blind --merge`, the chunks of `ddct-fleet blind` on a Dask cluster) — so a merged
//! summary is the one a single run of the same trials gives.

use crate::truth::form::Family;
use crate::truth::{Band, TruthKind, Variants};
use serde::{Deserialize, Deserializer};

/// What the summary reads of a trial's truth.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct ScoredTruth {
    pub kind: TruthKind,
    pub family: Option<Family>,
    pub band: Band,
    #[serde(deserialize_with = "nan_if_null")]
    pub effect_size: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub raw_effect_size: f64,
    #[serde(deserialize_with = "nans_if_null")]
    pub effect_sizes: Vec<f64>,
    pub variants: Variants,
}

/// What the summary reads of a trial.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct Scored {
    pub index: usize,
    /// The truth's label (classes joined by `+`, `nominal`, `outside:KIND`).
    pub label: String,
    pub truth: ScoredTruth,
    pub first: String,
    pub correct: bool,
    pub ambiguous: bool,
    pub in_large_set: bool,
    pub extra_classes: usize,
    pub pair_named: usize,
    pub recalibration_findings: usize,
    pub outside_findings: usize,
    #[serde(deserialize_with = "nan_if_null")]
    pub reduction_pct: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub gap_reduction_pct: f64,
    pub seconds: f64,
    pub error: Option<String>,
}

/// JSON writes a number that is not finite as `null`: read it back as NaN.
fn nan_if_null<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

fn nans_if_null<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
    Ok(Vec::<Option<f64>>::deserialize(d)?
        .into_iter()
        .map(|v| v.unwrap_or(f64::NAN))
        .collect())
}

impl Scored {
    /// A trial as written in a report's `trials` array.
    pub fn from_json(v: &serde_json::Value) -> Result<Scored, serde_json::Error> {
        Scored::deserialize(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn null_numbers_read_back_as_nan() {
        let v = serde_json::json!({
            "index": 3, "label": "nominal",
            "truth": {"kind": "nominal", "family": null, "band": "<1", "effect_size": 0.0,
                      "raw_effect_size": null, "effect_sizes": [null, 2.0],
                      "variants": {"only_req1": false, "worn_validation": true}, "seed": 1},
            "first": "none", "correct": true, "ambiguous": false, "in_large_set": false,
            "extra_classes": 0, "pair_named": 0, "recalibration_findings": 1,
            "outside_findings": 0, "reduction_pct": null, "gap_reduction_pct": 12.5,
            "seconds": 4.0, "error": null, "output": "torque", "findings": []
        });
        let s = Scored::from_json(&v).unwrap();
        assert_eq!(s.truth.kind, TruthKind::Nominal);
        assert_eq!(s.truth.band, Band::Below1);
        assert!(s.truth.raw_effect_size.is_nan() && s.reduction_pct.is_nan());
        assert!(s.truth.effect_sizes[0].is_nan() && s.truth.effect_sizes[1] == 2.0);
        assert!(s.truth.variants.worn_validation && s.gap_reduction_pct == 12.5);
        let bad = serde_json::json!({"index": 3});
        assert!(Scored::from_json(&bad).is_err());
    }
}
