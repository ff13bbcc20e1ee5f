//! The typed result of the diagnosis (issue 17): a list of findings, each a class that explains
//! part of the gap (physics or sensor), a recalibration that had to leave its plausible range,
//! or a residual no class explains ("outside the library") — or `Nothing`, alone, when the
//! validation residual is at the noise floor and every recalibrated parameter is plausible.

use crate::gap::model::class::{ClassId, Variable};
use crate::model::effects::Subsystem;
use std::collections::BTreeMap;

/// A class that explains part of the validation gap.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ClassFinding {
    pub class: ClassId,
    pub subsystem: Subsystem,
    pub variable: Variable,
    /// Other classes that explain the validation data equally well (the ambiguity set is this
    /// class plus these); empty when the class is singled out.
    pub ambiguous_with: Vec<ClassId>,
    /// Share of the recalibrated validation gap (above the noise floor) this class closes, in
    /// the order of selection (%; 0–100).
    pub share_pct: f64,
    /// Magnitude: the largest relative (or absolute, see `unit`) change the fitted term makes
    /// over the operating range of its variable in the records, with a 95 % interval.
    pub magnitude: f64,
    /// The 95 % interval: the noise's ([`Self::noise_ci95`]) and the form's error
    /// ([`Self::model_form_rel`]) added in quadrature (`gap::method::form_error`).
    pub magnitude_ci95: (f64, f64),
    /// The 95 % interval from the records' noise alone (the delta method).
    pub noise_ci95: (f64, f64),
    /// The relative standard deviation of the form's error: √ of what the diagnosed model
    /// leaves above the noise floor on the class's channels over what the class closed.
    pub model_form_rel: f64,
    pub unit: &'static str,
    /// What the magnitude is measured over (the variable's range, or a parameter).
    pub magnitude_basis: crate::gap::model::classes::Basis,
    /// When the magnitude lies outside the documented range of the class's library member:
    /// by how much (text), else `None`.
    pub range_warning: Option<String>,
    /// The fitted shape: (variable, value of the term) at the knots.
    pub shape: Vec<(f64, f64)>,
    /// Fitted parameters by name.
    pub parameters: BTreeMap<String, f64>,
}

/// A recalibrated parameter that had to move outside its plausible range.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RecalibrationFinding {
    pub key: crate::gap::model::keys::ParamKey,
    pub nominal: f64,
    pub value: f64,
    /// Move from nominal (%).
    pub move_pct: f64,
    /// Plausible range of the recalibrated value.
    pub plausible: (f64, f64),
}

/// A residual no class explains.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct OutsideFinding {
    pub subsystem: Subsystem,
    /// Validation excess over the noise floor left unexplained (mean standardized square − 1).
    pub excess: f64,
    /// Measured variables the remaining residual depends on, strongest first.
    pub depends_on: Vec<String>,
    /// Time structure of the remaining residual (e.g. "slow drift", "within engagements").
    pub time_structure: String,
}

/// One finding of the diagnosis.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Finding {
    /// A physics class explains part of the gap.
    Class(ClassFinding),
    /// A sensor class explains part of the gap.
    Sensor(ClassFinding),
    /// A recalibration outside its plausible range is itself the finding.
    Recalibration(RecalibrationFinding),
    /// A significant residual no class explains.
    OutsideLibrary(OutsideFinding),
    /// Nothing significant remains (only ever alone).
    Nothing,
}

/// What a finding names as an effect: its class, or the kind of finding. Its `Display` (and
/// JSON) is the one label of reports, tables and blind trials: the class's identifier,
/// `recalibration`, `outside_library` or `none`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    Class(ClassId),
    Recalibration,
    OutsideLibrary,
    None,
}

impl Effect {
    pub fn as_str(self) -> &'static str {
        match self {
            Effect::Class(c) => c.as_str(),
            Effect::Recalibration => "recalibration",
            Effect::OutsideLibrary => "outside_library",
            Effect::None => "none",
        }
    }
}

impl std::fmt::Display for Effect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.as_str())
    }
}

impl serde::Serialize for Effect {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

impl Finding {
    /// What the finding names.
    pub fn effect(&self) -> Effect {
        match self {
            Finding::Class(c) | Finding::Sensor(c) => Effect::Class(c.class),
            Finding::Recalibration(_) => Effect::Recalibration,
            Finding::OutsideLibrary(_) => Effect::OutsideLibrary,
            Finding::Nothing => Effect::None,
        }
    }

    /// The class finding, for physics and sensor classes.
    pub fn class(&self) -> Option<&ClassFinding> {
        match self {
            Finding::Class(c) | Finding::Sensor(c) => Some(c),
            _ => None,
        }
    }

    /// Identifier used in reports: the class, `recalibration`, `outside_library` or `none`.
    pub fn label(&self) -> String {
        match self {
            Finding::Class(c) | Finding::Sensor(c) => c.class.as_str().to_string(),
            Finding::Recalibration(r) => format!("recalibration:{}", r.key),
            Finding::OutsideLibrary(o) => format!("outside_library:{}", o.subsystem),
            Finding::Nothing => "none".to_string(),
        }
    }

    pub fn subsystem(&self) -> Option<Subsystem> {
        match self {
            Finding::Class(c) | Finding::Sensor(c) => Some(c.subsystem),
            Finding::OutsideLibrary(o) => Some(o.subsystem),
            Finding::Recalibration(r) => Some(r.key.subsystem()),
            Finding::Nothing => None,
        }
    }
}

/// Classes named by a list of findings, each with its ambiguity set (the class first).
pub fn named_classes(findings: &[Finding]) -> Vec<Vec<ClassId>> {
    findings
        .iter()
        .filter_map(Finding::class)
        .map(|c| {
            let mut v = vec![c.class];
            v.extend(c.ambiguous_with.iter().copied());
            v
        })
        .collect()
}

/// True when the findings claim no class and no outside-library residual.
pub fn is_nothing(findings: &[Finding]) -> bool {
    findings.iter().all(|f| matches!(f, Finding::Nothing))
}
