//! The blind test of the sim-to-real diagnosis against the independent truth generator
//! ([`crate::truth`], issue 17 item 6): per trial a hidden truth is drawn, its records are
//! generated as CSV text and parsed like any bench file, `gap::diagnose::diagnose` runs on them
//! with the nominal parameters, and the result is scored from its findings only
//! (`verdict.findings`).
//!
//! Scoring:
//! - class and sensor trials: correct when the truth's class is named alone (**direct**), or
//!   inside an ambiguity set of at most two classes (**ambiguous**, reported separately); a class
//!   named first inside a larger set does not count;
//! - nominal trials: correct when no class is claimed (no `Class`/`Sensor` finding);
//!   recalibration and outside-library findings are counted separately;
//! - outside trials: **attributed** when any class is claimed (the goal is at most 10 %);
//! - pairs: both classes named (each directly or in a set of at most two), and one of two; the
//!   goal counts the pairs whose weaker effect alone is at least 1× the noise (the generator
//!   draws pair members from the upper half of their ranges, so most are), all pairs are shown;
//! - gap reduction: `how_far.gap_reduction_pct` (and `reduction_pct`) of correct trials.
//!
//! Trials are deterministic in (seed, index) and independent: [`run`] spreads them over threads.

mod scored;

pub use scored::{Scored, ScoredTruth};

use crate::gap::method::diagnose::{diagnose, DiagnoseOptions};
use crate::gap::method::finding::{named_classes, Finding};
use crate::gap::model::class::ClassId;
use crate::model::params::Params;
use crate::plot::{Figure, LegendPos, Panel, Series, Style};
use crate::records::dataset::Dataset;
use crate::truth::{self, Band, Truth, TruthKind};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::time::Instant;

/// The score of one trial.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TrialResult {
    pub index: usize,
    pub truth: Truth,
    /// The truth's label ([`Truth::label`]).
    pub label: String,
    /// Labels of every finding, in order.
    pub findings: Vec<String>,
    /// Named classes with their ambiguity sets (the class first).
    pub named: Vec<Vec<ClassId>>,
    /// The first named class, else the first finding's kind (`outside_library`,
    /// `recalibration`, `none`), else `error`.
    pub first: String,
    /// The trial is scored correct (see the module documentation).
    pub correct: bool,
    /// Correct only through an ambiguity set of two.
    pub ambiguous: bool,
    /// Class and sensor trials: the truth's class named first inside a set larger than two.
    pub in_large_set: bool,
    /// Classes named beyond the truth's (class, sensor and pair trials) or at all (nominal and
    /// outside trials).
    pub extra_classes: usize,
    /// Pairs: how many of the two classes are named.
    pub pair_named: usize,
    pub recalibration_findings: usize,
    pub outside_findings: usize,
    /// Validation RMSE reduction and gap-above-noise reduction of the main output (%).
    pub reduction_pct: f64,
    pub gap_reduction_pct: f64,
    pub output: String,
    pub seconds: f64,
    pub error: Option<String>,
}

impl TrialResult {
    /// This trial as the summary reads it, through its JSON (the path merged trials take).
    pub fn scored(&self) -> Result<Scored, serde_json::Error> {
        Scored::from_json(&serde_json::to_value(self)?)
    }
}

/// Whether the class `c` is named alone or in a set of at most two.
fn named_within(named: &[Vec<ClassId>], c: ClassId) -> Option<bool> {
    if named.iter().any(|s| s.len() == 1 && s[0] == c) {
        return Some(false);
    }
    if named.iter().any(|s| s.len() <= 2 && s.contains(&c)) {
        return Some(true);
    }
    None
}

/// The verdict of one trial from the named classes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Verdict {
    pub correct: bool,
    pub ambiguous: bool,
    pub in_large_set: bool,
    pub pair_named: usize,
}

/// Scores the named classes (each with its ambiguity set, the class first) and the claimed
/// classes (every `Class`/`Sensor` finding) against a truth of `kind` with `classes`.
pub fn classify(
    kind: TruthKind,
    classes: &[ClassId],
    named: &[Vec<ClassId>],
    claimed: &[ClassId],
) -> Verdict {
    let mut v = Verdict::default();
    match kind {
        TruthKind::Class | TruthKind::Sensor => {
            let c = classes[0];
            match named_within(named, c) {
                Some(amb) => {
                    v.correct = true;
                    v.ambiguous = amb;
                }
                None => v.in_large_set = named.iter().any(|s| s[0] == c),
            }
        }
        TruthKind::Pair => {
            let hits: Vec<Option<bool>> = classes.iter().map(|c| named_within(named, *c)).collect();
            v.pair_named = hits.iter().filter(|h| h.is_some()).count();
            v.correct = v.pair_named == classes.len();
            v.ambiguous = v.correct && hits.contains(&Some(true));
        }
        TruthKind::Nominal | TruthKind::Outside => v.correct = claimed.is_empty(),
    }
    v
}

/// Scores findings against a truth.
pub fn score(
    index: usize,
    truth: &Truth,
    findings: &[Finding],
    reduction_pct: f64,
    gap_reduction_pct: f64,
    output: &str,
) -> TrialResult {
    let named = named_classes(findings);
    let claimed: Vec<ClassId> = findings
        .iter()
        .filter_map(Finding::class)
        .map(|c| c.class)
        .collect();
    let first = findings
        .iter()
        .find(|f| f.class().is_some())
        .or(findings.first())
        .map(|f| f.effect().to_string())
        .unwrap_or_else(|| "none".into());
    let mut r = TrialResult {
        index,
        truth: truth.clone(),
        label: truth.label(),
        findings: findings.iter().map(Finding::label).collect(),
        named: named.clone(),
        first,
        correct: false,
        ambiguous: false,
        in_large_set: false,
        extra_classes: claimed
            .iter()
            .filter(|c| !truth.classes.contains(c))
            .count(),
        pair_named: 0,
        recalibration_findings: findings
            .iter()
            .filter(|f| matches!(f, Finding::Recalibration(_)))
            .count(),
        outside_findings: findings
            .iter()
            .filter(|f| matches!(f, Finding::OutsideLibrary(_)))
            .count(),
        reduction_pct,
        gap_reduction_pct,
        output: output.to_string(),
        seconds: 0.0,
        error: None,
    };
    let v = classify(truth.kind, &truth.classes, &named, &claimed);
    r.correct = v.correct;
    r.ambiguous = v.ambiguous;
    r.in_large_set = v.in_large_set;
    r.pair_named = v.pair_named;
    r
}

/// Which truths a blind run draws.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Draw {
    /// The campaign's: kinds in blocks of ten, classes in turn.
    #[default]
    Campaign,
    /// Every trial's effect this class (its magnitude, form, detuning and noise drawn from the
    /// seed and the index): a class's own blind trials.
    Class(truth::Injected),
}

/// Runs trial `index`: draws the truth, generates and parses its records, diagnoses on
/// `threads` threads (at least 1), scores.
pub fn run_trial(
    seed: u64,
    index: usize,
    nominal: &Params,
    threads: usize,
    draw: Draw,
) -> TrialResult {
    let t0 = Instant::now();
    let (truth, recs) = match draw {
        Draw::Campaign => truth::draw_and_records(seed, index, nominal),
        Draw::Class(c) => truth::draw_class_and_records(seed, index, nominal, c),
    };
    let parse = |v: &[(String, String)]| -> Result<Vec<Dataset>, String> {
        v.iter()
            .map(|(name, csv)| Dataset::from_csv(name, csv).map_err(|e| e.to_string()))
            .collect()
    };
    let opts = DiagnoseOptions {
        carry_energy: truth.variants.worn_validation,
        threads,
        ..DiagnoseOptions::default()
    };
    let outcome = parse(&recs.train).and_then(|tr| {
        let va = parse(&recs.validate)?;
        diagnose(&tr, &va, nominal, &opts).map_err(|e| e.to_string())
    });
    let mut r = match outcome {
        Ok(d) => score(
            index,
            &truth,
            &d.verdict.findings,
            d.how_far.reduction_pct,
            d.how_far.gap_reduction_pct,
            &d.how_far.output,
        ),
        Err(e) => {
            let mut r = score(index, &truth, &[], f64::NAN, f64::NAN, "");
            r.correct = false;
            r.first = "error".into();
            r.error = Some(e);
            r
        }
    };
    r.seconds = t0.elapsed().as_secs_f64();
    r
}

/// The indices among `first`..`first + trials` whose kind is in `kinds` (every index when
/// `kinds` is empty): a subset of a run is the same trials as in the whole run.
pub fn indices(seed: u64, first: usize, trials: usize, kinds: &[TruthKind]) -> Vec<usize> {
    (first..first + trials)
        .filter(|&i| kinds.is_empty() || kinds.contains(&truth::kind_of(seed, i).0))
        .collect()
}

/// Runs the trials `indices` on `threads` threads; `on_done` sees each result as it finishes.
/// Results are returned in index order.
pub fn run(
    seed: u64,
    indices: &[usize],
    threads: usize,
    nominal: &Params,
    draw: Draw,
    on_done: &(dyn Fn(&TrialResult) + Sync),
) -> Vec<TrialResult> {
    // The trials share the cores: each diagnosis takes its share (a diagnosis's fits on one
    // thread keep every replay in one memo; its result does not depend on the threads). The last
    // trials to start take every core: the others finish while they run.
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads = threads.clamp(1, indices.len().max(1));
    let share = (cores / threads).max(1);
    let tail = indices.len().saturating_sub(threads - 1);
    let mut v = crate::par::map(threads, indices, |q, &i| {
        let inner = if q >= tail { cores } else { share };
        let r = run_trial(seed, i, nominal, inner, draw);
        on_done(&r);
        r
    });
    v.sort_by_key(|r| r.index);
    v
}

/// Accuracy of a group of trials.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Rate {
    pub n: usize,
    pub correct: usize,
    pub ambiguous: usize,
    /// Correct (direct or ambiguous) (%).
    pub accuracy_pct: f64,
    /// Correct only through an ambiguity set (%).
    pub ambiguity_pct: f64,
    /// Median validation gap reduction on the correct trials (%).
    pub median_gap_reduction_pct: f64,
    pub median_reduction_pct: f64,
}

fn pct(a: usize, b: usize) -> f64 {
    if b == 0 {
        f64::NAN
    } else {
        100.0 * a as f64 / b as f64
    }
}

fn median(v: &[f64]) -> f64 {
    let mut v: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

impl Rate {
    pub fn of(rs: &[&Scored]) -> Rate {
        let correct: Vec<&&Scored> = rs.iter().filter(|r| r.correct).collect();
        let ambiguous = rs.iter().filter(|r| r.ambiguous).count();
        Rate {
            n: rs.len(),
            correct: correct.len(),
            ambiguous,
            accuracy_pct: pct(correct.len(), rs.len()),
            ambiguity_pct: pct(ambiguous, rs.len()),
            median_gap_reduction_pct: median(
                &correct
                    .iter()
                    .map(|r| r.gap_reduction_pct)
                    .collect::<Vec<_>>(),
            ),
            median_reduction_pct: median(
                &correct.iter().map(|r| r.reduction_pct).collect::<Vec<_>>(),
            ),
        }
    }
}

/// One bin of the detectability curve.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DetectBin {
    /// Effect size over the noise: [lo, hi).
    pub lo: f64,
    pub hi: f64,
    pub n: usize,
    pub correct: usize,
    pub direct: usize,
    pub accuracy_pct: f64,
    pub direct_pct: f64,
}

/// An acceptance criterion of issue 17 with the measured value.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Criterion {
    pub name: String,
    pub value_pct: f64,
    pub n: usize,
    /// Goal: at least (`at_least`) or at most this value (%).
    pub goal_pct: f64,
    pub at_least: bool,
    pub met: bool,
}

/// Summary of a blind run.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Summary {
    pub trials: usize,
    pub errors: usize,
    pub mean_seconds_per_trial: f64,
    pub by_kind: BTreeMap<String, Rate>,
    /// Class and sensor trials together.
    pub class_trials: Rate,
    pub by_class: BTreeMap<String, Rate>,
    /// Class and sensor trials per magnitude band (identifiable effect size over the noise).
    pub by_band: BTreeMap<String, Rate>,
    /// Class and sensor trials per band of the raw effect size (against the truth's own
    /// baseline, nothing refitted).
    pub by_raw_band: BTreeMap<String, Rate>,
    /// Class and sensor trials per form family.
    pub by_family: BTreeMap<String, Rate>,
    /// Nominal trials: with a recalibration finding, with an outside-library finding (counts).
    pub nominal_with_recalibration: usize,
    pub nominal_with_outside: usize,
    /// Outside trials attributed to a class (%), and flagged outside the library (%).
    pub outside_attributed_pct: f64,
    pub outside_flagged_pct: f64,
    /// Pairs: both named (%), at least one named (%).
    pub pairs_both_pct: f64,
    pub pairs_one_pct: f64,
    /// Pairs whose weaker effect alone is at least 1× the noise: how many, and both named (%).
    /// The criterion counts these: an effect below the noise cannot be named without claiming
    /// classes on nominal records too (the single-class trials' `<1` band shows those).
    pub pairs_detectable: usize,
    pub pairs_detectable_both_pct: f64,
    /// Class and sensor trials whose class led a set of more than two (count).
    pub in_large_set: usize,
    /// confusion[truth][first named finding] = count.
    pub confusion: BTreeMap<String, BTreeMap<String, usize>>,
    pub detectability: Vec<DetectBin>,
    pub acceptance: Vec<Criterion>,
}

/// Edges of the detectability bins (effect size over the noise).
pub const DETECT_EDGES: [f64; 9] = [0.0, 0.5, 1.0, 2.0, 3.0, 5.0, 10.0, 30.0, f64::INFINITY];

/// Summarises results.
pub fn summarize(results: &[Scored]) -> Summary {
    let of_kind =
        |k: TruthKind| -> Vec<&Scored> { results.iter().filter(|r| r.truth.kind == k).collect() };
    let class_trials: Vec<&Scored> = results
        .iter()
        .filter(|r| matches!(r.truth.kind, TruthKind::Class | TruthKind::Sensor))
        .collect();
    let group = |key: &dyn Fn(&Scored) -> String| grouped(&class_trials, key);
    let by_band = group(&|r| r.truth.band.as_str().to_string());
    let nominal = of_kind(TruthKind::Nominal);
    let outside = of_kind(TruthKind::Outside);
    let pairs = of_kind(TruthKind::Pair);
    let attributed = outside.iter().filter(|r| !r.correct).count();
    let both = pairs.iter().filter(|r| r.correct).count();
    let detectable: Vec<&Scored> = pairs
        .iter()
        .copied()
        .filter(|r| r.truth.effect_sizes.iter().all(|e| *e >= 1.0))
        .collect();
    let acceptance = acceptance(results, &by_band, &nominal, &outside, &detectable);
    Summary {
        trials: results.len(),
        errors: results.iter().filter(|r| r.error.is_some()).count(),
        mean_seconds_per_trial: results.iter().map(|r| r.seconds).sum::<f64>()
            / results.len().max(1) as f64,
        by_kind: rates_by_kind(results),
        class_trials: Rate::of(&class_trials),
        by_class: group(&|r| r.label.clone()),
        by_band,
        by_raw_band: group(&|r| Band::of(r.truth.raw_effect_size).as_str().to_string()),
        by_family: group(&|r| {
            r.truth
                .family
                .map(|f| f.as_str().to_string())
                .unwrap_or_default()
        }),
        nominal_with_recalibration: nominal
            .iter()
            .filter(|r| r.recalibration_findings > 0)
            .count(),
        nominal_with_outside: nominal.iter().filter(|r| r.outside_findings > 0).count(),
        outside_attributed_pct: pct(attributed, outside.len()),
        outside_flagged_pct: pct(
            outside.iter().filter(|r| r.outside_findings > 0).count(),
            outside.len(),
        ),
        pairs_both_pct: pct(both, pairs.len()),
        pairs_one_pct: pct(
            pairs.iter().filter(|r| r.pair_named >= 1).count(),
            pairs.len(),
        ),
        pairs_detectable: detectable.len(),
        pairs_detectable_both_pct: pct(
            detectable.iter().filter(|r| r.correct).count(),
            detectable.len(),
        ),
        in_large_set: class_trials.iter().filter(|r| r.in_large_set).count(),
        confusion: confusion(results),
        detectability: detectability(&class_trials),
        acceptance,
    }
}

/// Accuracy per kind of truth (no gap reduction for nominal and outside truths: nothing to
/// shrink, no gap was put in or none is attributable).
fn rates_by_kind(results: &[Scored]) -> BTreeMap<String, Rate> {
    let mut by_kind = BTreeMap::new();
    for k in TruthKind::ALL {
        let v: Vec<&Scored> = results.iter().filter(|r| r.truth.kind == k).collect();
        if !v.is_empty() {
            let mut r = Rate::of(&v);
            if matches!(k, TruthKind::Nominal | TruthKind::Outside) {
                r.median_gap_reduction_pct = f64::NAN;
                r.median_reduction_pct = f64::NAN;
            }
            by_kind.insert(k.as_str().to_string(), r);
        }
    }
    by_kind
}

/// Accuracy of `trials` grouped by `key`.
fn grouped(trials: &[&Scored], key: &dyn Fn(&Scored) -> String) -> BTreeMap<String, Rate> {
    let mut m: BTreeMap<String, Vec<&Scored>> = BTreeMap::new();
    for r in trials {
        m.entry(key(r)).or_default().push(r);
    }
    m.into_iter().map(|(k, v)| (k, Rate::of(&v))).collect()
}

/// Counts of first findings per hidden truth (pairs in one row).
fn confusion(results: &[Scored]) -> BTreeMap<String, BTreeMap<String, usize>> {
    let mut confusion: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    for r in results {
        let row = match r.truth.kind {
            TruthKind::Pair => "pair".to_string(),
            _ => r.label.clone(),
        };
        *confusion
            .entry(row)
            .or_default()
            .entry(r.first.clone())
            .or_default() += 1;
    }
    confusion
}

/// Accuracy of the class and sensor trials per bin of effect size ([`DETECT_EDGES`]).
fn detectability(class_trials: &[&Scored]) -> Vec<DetectBin> {
    DETECT_EDGES
        .windows(2)
        .map(|w| {
            let v: Vec<&&Scored> = class_trials
                .iter()
                .filter(|r| r.truth.effect_size >= w[0] && r.truth.effect_size < w[1])
                .collect();
            let correct = v.iter().filter(|r| r.correct).count();
            let direct = v.iter().filter(|r| r.correct && !r.ambiguous).count();
            DetectBin {
                lo: w[0],
                hi: w[1],
                n: v.len(),
                correct,
                direct,
                accuracy_pct: pct(correct, v.len()),
                direct_pct: pct(direct, v.len()),
            }
        })
        .collect()
}

/// The acceptance criteria of issue 17 with their values.
fn acceptance(
    results: &[Scored],
    by_band: &BTreeMap<String, Rate>,
    nominal: &[&Scored],
    outside: &[&Scored],
    detectable: &[&Scored],
) -> Vec<Criterion> {
    let band_rate = |b: Band| -> (f64, usize) {
        by_band
            .get(b.as_str())
            .map_or((f64::NAN, 0), |r| (r.accuracy_pct, r.n))
    };
    let nominal_rate = Rate::of(nominal);
    let attributed = outside.iter().filter(|r| !r.correct).count();
    let correct_all: Vec<f64> = results
        .iter()
        .filter(|r| r.correct && !matches!(r.truth.kind, TruthKind::Nominal | TruthKind::Outside))
        .map(|r| r.gap_reduction_pct)
        .collect();
    let crit = |name: &str, (value, n): (f64, usize), goal: f64, at_least: bool| Criterion {
        name: name.to_string(),
        value_pct: value,
        n,
        goal_pct: goal,
        at_least,
        met: n > 0
            && if at_least {
                value >= goal
            } else {
                value <= goal
            },
    };
    vec![
        crit(
            "class trials above 3x the noise: correct class (or in a set of two)",
            band_rate(Band::Above3),
            90.0,
            true,
        ),
        crit(
            "class trials 1-3x the noise: correct class (or in a set of two)",
            band_rate(Band::From1To3),
            75.0,
            true,
        ),
        crit(
            "nominal trials (detuned baselines): no class claimed",
            (nominal_rate.accuracy_pct, nominal.len()),
            90.0,
            true,
        ),
        crit(
            "outside trials attributed to a class",
            (pct(attributed, outside.len()), outside.len()),
            10.0,
            false,
        ),
        crit(
            "pairs, each effect at least 1x the noise: both classes named",
            (
                pct(
                    detectable.iter().filter(|r| r.correct).count(),
                    detectable.len(),
                ),
                detectable.len(),
            ),
            70.0,
            true,
        ),
        crit(
            "median validation gap reduction on correct trials",
            (median(&correct_all), correct_all.len()),
            70.0,
            true,
        ),
    ]
}

fn f1(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.1}")
    } else {
        "–".into()
    }
}

/// The report as text: one line per trial, the tables, the confusion matrix, the criteria.
pub fn render_text(results: &[Scored], s: &Summary) -> String {
    let mut o = String::new();
    trial_lines(&mut o, results);
    rate_tables(&mut o, s);
    detectability_lines(&mut o, s);
    confusion_matrix(&mut o, s);
    pair_and_outside_lines(&mut o, s);
    acceptance_lines(&mut o, s);
    let _ = writeln!(
        o,
        "\n{} trial(s), {} error(s), {:.1} s per trial (one thread)",
        s.trials, s.errors, s.mean_seconds_per_trial
    );
    o
}

/// One line per trial: its truth, sizes and band, the first finding and whether it was right.
fn trial_lines(o: &mut String, results: &[Scored]) {
    let _ = writeln!(
        o,
        "{:>4}  {:<8} {:<44} {:<16} {:>7} {:>7} {:<4} {:<28} {:>4} {:>7}",
        "#", "kind", "truth", "family", "raw", "size", "band", "first finding", "ok", "gap %"
    );
    for r in results {
        let t = &r.truth;
        let mut label = r.label.clone();
        if t.variants.only_req1 {
            label.push_str(" [req1]");
        }
        if t.variants.worn_validation {
            label.push_str(" [worn]");
        }
        let _ = writeln!(
            o,
            "{:>4}  {:<8} {:<44} {:<16} {:>7.2} {:>7.2} {:<4} {:<28} {:>4} {:>7}",
            r.index,
            t.kind.as_str(),
            label,
            t.family.map(|f| f.as_str()).unwrap_or("-"),
            t.raw_effect_size,
            t.effect_size,
            t.band.as_str(),
            if r.error.is_some() {
                "error".to_string()
            } else {
                r.first.clone()
            },
            if r.correct {
                if r.ambiguous {
                    "amb"
                } else {
                    "yes"
                }
            } else {
                "NO"
            },
            if matches!(t.kind, TruthKind::Nominal | TruthKind::Outside) {
                "–".to_string()
            } else {
                f1(r.gap_reduction_pct)
            }
        );
        if let Some(e) = &r.error {
            let _ = writeln!(o, "      error: {e}");
        }
    }
}

/// Accuracy per group of one summary table.
fn rate_table(o: &mut String, title: &str, m: &BTreeMap<String, Rate>) {
    let _ = writeln!(o, "\n{title}");
    let _ = writeln!(
        o,
        "  {:<34} {:>4} {:>10} {:>12} {:>16}",
        "", "n", "accuracy %", "ambiguous %", "median gap red. %"
    );
    for (k, r) in m {
        let _ = writeln!(
            o,
            "  {:<34} {:>4} {:>10} {:>12} {:>16}",
            k,
            r.n,
            f1(r.accuracy_pct),
            f1(r.ambiguity_pct),
            f1(r.median_gap_reduction_pct)
        );
    }
}

/// The accuracy tables: per kind, class, magnitude band (identifiable and raw) and form family.
fn rate_tables(o: &mut String, s: &Summary) {
    rate_table(o, "per kind", &s.by_kind);
    rate_table(o, "class and sensor trials per class", &s.by_class);
    rate_table(
        o,
        "class and sensor trials per magnitude band (identifiable effect size over the noise: \
         what no baseline within ±20 % reproduces)",
        &s.by_band,
    );
    rate_table(
        o,
        "class and sensor trials per band of the raw effect size (against the truth's own \
         baseline)",
        &s.by_raw_band,
    );
    rate_table(o, "class and sensor trials per form family", &s.by_family);
}

/// The detectability curve's bins.
fn detectability_lines(o: &mut String, s: &Summary) {
    let _ = writeln!(
        o,
        "\ndetectability (class and sensor trials, effect size over the noise):"
    );
    for b in &s.detectability {
        let _ = writeln!(
            o,
            "  [{:>5}, {:>5})  n {:>4}  correct {:>6} %  named alone {:>6} %",
            b.lo,
            if b.hi.is_finite() {
                format!("{}", b.hi)
            } else {
                "∞".into()
            },
            b.n,
            f1(b.accuracy_pct),
            f1(b.direct_pct)
        );
    }
}

/// The confusion matrix of hidden truths against first named classes.
fn confusion_matrix(o: &mut String, s: &Summary) {
    let _ = writeln!(
        o,
        "\nconfusion matrix (rows: hidden truth; columns: first named class, else the first finding):"
    );
    let mut cols: Vec<String> = s
        .confusion
        .values()
        .flat_map(|m| m.keys().cloned())
        .collect();
    cols.sort();
    cols.dedup();
    let short = |c: &str| -> String { c.chars().take(11).collect() };
    let _ = write!(o, "  {:<34}", "");
    for c in &cols {
        let _ = write!(o, " {:>11}", short(c));
    }
    let _ = writeln!(o);
    for (t, row) in &s.confusion {
        let _ = write!(o, "  {t:<34}");
        for c in &cols {
            match row.get(c) {
                Some(n) => {
                    let _ = write!(o, " {n:>11}");
                }
                None => {
                    let _ = write!(o, " {:>11}", ".");
                }
            }
        }
        let _ = writeln!(o);
    }
    let _ = writeln!(o, "  columns: {}", cols.join(", "));
}

/// The nominal, outside and pair trials' summary lines.
fn pair_and_outside_lines(o: &mut String, s: &Summary) {
    let _ = writeln!(
        o,
        "\nnominal trials with a recalibration finding: {}; with an outside-library finding: {}",
        s.nominal_with_recalibration, s.nominal_with_outside
    );
    let _ = writeln!(
        o,
        "outside trials attributed to a class: {} %; flagged outside the library: {} %",
        f1(s.outside_attributed_pct),
        f1(s.outside_flagged_pct)
    );
    let _ = writeln!(
        o,
        "pairs: both named {} %, at least one {} %; class led a set of more than two: {} trial(s)",
        f1(s.pairs_both_pct),
        f1(s.pairs_one_pct),
        s.in_large_set
    );
    let _ = writeln!(
        o,
        "pairs whose weaker effect is at least 1x the noise: {}, both named {} %",
        s.pairs_detectable,
        f1(s.pairs_detectable_both_pct)
    );
}

/// The acceptance criteria with their values and goals.
fn acceptance_lines(o: &mut String, s: &Summary) {
    let _ = writeln!(o, "\nacceptance (issue 17):");
    for c in &s.acceptance {
        let _ = writeln!(
            o,
            "  {:<70} {:>6} % (n {:>3}; goal {} {} %) {}",
            c.name,
            f1(c.value_pct),
            c.n,
            if c.at_least { "≥" } else { "≤" },
            c.goal_pct,
            match (c.n, c.met) {
                (0, _) => "no trials",
                (_, true) => "met",
                (_, false) => "NOT met",
            }
        );
    }
}

/// The detectability curve as SVG: accuracy of the class and sensor trials against the effect
/// size over the noise (bins of [`DETECT_EDGES`], drawn at their geometric centres on a log axis),
/// and per magnitude band.
pub fn detectability_svg(s: &Summary) -> String {
    let centre = |b: &DetectBin| -> f64 {
        let lo = if b.lo > 0.0 { b.lo } else { 0.25 };
        let hi = if b.hi.is_finite() { b.hi } else { 2.0 * b.lo };
        (lo * hi).sqrt().log10()
    };
    let pts = |direct: bool| -> Vec<(f64, f64)> {
        s.detectability
            .iter()
            .filter(|b| b.n > 0)
            .map(|b| {
                (
                    centre(b),
                    if direct { b.direct_pct } else { b.accuracy_pct },
                )
            })
            .collect()
    };
    let mut p = Panel::new(
        "Accuracy vs effect size",
        "log10(effect size / noise)",
        "correct (%)",
    )
    .y_range(0.0, 100.0)
    .legend_pos(LegendPos::BottomRight);
    p.add(Series::line("correct or in a set of two", pts(false)));
    p.add(Series::line("named alone", pts(true)).style(Style::Dashed));
    let mut q = Panel::new(
        "Accuracy per magnitude band",
        "band (0: <1, 1: 1-3, 2: >3 × noise)",
        "correct (%)",
    )
    .y_range(0.0, 100.0)
    .x_range(-0.5, 2.5)
    .legend_pos(LegendPos::BottomRight);
    let bands: Vec<(f64, f64)> = Band::ALL
        .iter()
        .enumerate()
        .filter_map(|(k, b)| {
            s.by_band
                .get(b.as_str())
                .map(|r| (k as f64, r.accuracy_pct))
        })
        .collect();
    q.add(Series::line("class and sensor trials", bands).style(Style::Markers));
    Figure::new(
        format!(
            "Blind test against the independent truth generator ({} trials)",
            s.trials
        ),
        2,
    )
    .panel(p)
    .panel(q)
    .to_svg()
}

#[cfg(test)]
mod tests {
    use super::*;
    use ClassId as C;

    #[test]
    fn scoring_rules() {
        let k = TruthKind::Class;
        let t = [C::SpringTemperature];
        // Named alone: direct.
        let v = classify(
            k,
            &t,
            &[vec![C::SpringTemperature]],
            &[C::SpringTemperature],
        );
        assert!(v.correct && !v.ambiguous);
        // In a set of two, either position: ambiguous but correct.
        let v = classify(
            k,
            &t,
            &[vec![C::FrictionTemperature, C::SpringTemperature]],
            &[C::FrictionTemperature],
        );
        assert!(v.correct && v.ambiguous);
        // Leading a set of three: not correct, reported.
        let set = vec![
            C::SpringTemperature,
            C::FrictionTemperature,
            C::KissPointTemperature,
        ];
        let v = classify(k, &t, &[set], &[C::SpringTemperature]);
        assert!(!v.correct && v.in_large_set);
        // Another class: wrong.
        let v = classify(
            k,
            &t,
            &[vec![C::FrictionClampLoad]],
            &[C::FrictionClampLoad],
        );
        assert!(!v.correct && !v.in_large_set);
        // Nominal and outside: any claimed class fails.
        for kind in [TruthKind::Nominal, TruthKind::Outside] {
            assert!(classify(kind, &[], &[], &[]).correct);
            assert!(!classify(kind, &[], &[vec![C::SensorTorque]], &[C::SensorTorque]).correct);
        }
        // Pairs: both, one.
        let pair = [C::SensorTorque, C::ActuatorLag];
        let v = classify(
            TruthKind::Pair,
            &pair,
            &[
                vec![C::ActuatorLag],
                vec![C::SensorTorque, C::FrictionClampLoad],
            ],
            &[C::ActuatorLag, C::SensorTorque],
        );
        assert!(v.correct && v.ambiguous && v.pair_named == 2);
        let v = classify(
            TruthKind::Pair,
            &pair,
            &[vec![C::ActuatorLag]],
            &[C::ActuatorLag],
        );
        assert!(!v.correct && v.pair_named == 1);
    }
}
