//! `ddct identify` and `ddct gap`: parameter identification and sim-to-real diagnosis (issue 7).
//! Wiring only: load files, call `ddct::gap`, write the outputs, print summaries.

use anyhow::{bail, Context};
use clap::{Args, Subcommand};
use ddct::blind::{self, TrialResult};
use ddct::can::logfile;
use ddct::experiment::plant::{self, PlantTruth};
use ddct::gap::method::diagnose::{diagnose, DiagnoseOptions, Diagnosis};
use ddct::gap::model::class::ClassId;
use ddct::gap::model::keys::ParamKey;
use ddct::gap::report::findings_table;
use ddct::gap::report::render;
use ddct::identify::{identify, Identification, IdentifyOptions};
use ddct::model::effects::EffectId;
use ddct::model::Params;
use ddct::records::dataset::{Dataset, Segments};
use ddct::truth::form::Family;
use ddct::truth::inject::{OutsideKind, Target};
use ddct::truth::{self, CaseSpec, Truth, TruthKind, Variants};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

#[derive(Debug, Args)]
pub struct IdentifyArgs {
    /// Identification records (candump `-l` logs or CSV), in time order.
    #[arg(long, num_args = 1.., required = true)]
    train: Vec<PathBuf>,
    /// Validation records (a different experiment), for the fit %.
    #[arg(long, num_args = 1..)]
    validate: Vec<PathBuf>,
    /// Initial parameter file (default: the built-in config/params.toml).
    #[arg(long, env = "DDCT_PARAMS")]
    params: Option<PathBuf>,
    /// Where to write the identified parameter file.
    #[arg(long)]
    out: PathBuf,
    /// Print the result as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// Skip the joint refinement (step 5): the paper's staged procedure only.
    #[arg(long)]
    staged_only: bool,
    /// Reference parameter file (e.g. the plant's truth) shown beside every estimate, with
    /// whether it lies inside the 95 % interval and the relative error.
    #[arg(long)]
    reference: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// Training records from "reality" (candump `-l` logs, MDF 4 bus logs or CSV).
    #[arg(long, num_args = 1.., required = true)]
    train: Vec<PathBuf>,
    /// Validation records (held out; effects are ranked on these).
    #[arg(long, num_args = 1.., required = true)]
    validate: Vec<PathBuf>,
    /// Nominal parameter file (default: the built-in config/params.toml).
    #[arg(long, env = "DDCT_PARAMS")]
    params: Option<PathBuf>,
    /// Output directory (report.md, report.json, SVG plots, calibration).
    #[arg(long)]
    out: PathBuf,
    /// Print report.json on stdout.
    #[arg(long)]
    json: bool,
    /// TCU calibration template (default: config/tcu.toml if it exists): a copy pointing at the
    /// written params.toml and effects.toml is written as tcu.toml.
    #[arg(long)]
    tcu_template: Option<PathBuf>,
    /// Friction energy accumulates across the files in the given order (default: per file).
    #[arg(long)]
    carry_energy: bool,
    /// Bootstrap resamples.
    #[arg(long, default_value_t = 400)]
    bootstrap: usize,
    /// Seed of the bootstrap.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Worker threads for loading the records and fitting the classes (default: the available
    /// cores; 1 where a scheduler such as `ddct-fleet` runs one diagnosis per core).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..))]
    threads: Option<u16>,
    /// Leave this class out of the diagnosis (repeatable), e.g. `sensor_speed` for speed
    /// channels calibrated on the bench: it is not fitted and the report lists it among the
    /// classes not checked.
    #[arg(long, value_name = "CLASS", value_parser = parse_class)]
    exclude_class: Vec<ClassId>,
    /// Append one row per finding to this Parquet table (created if missing): unit, log, start
    /// time, operating hours, kind, class, subsystem, variable, magnitude with its 95 %
    /// interval, share of the gap, gap closed, the finding as JSON, ddct version and a hash of
    /// the parameters. A diagnosis that fails appends an error row with the message.
    #[arg(long, value_name = "FILE.parquet")]
    findings: Option<PathBuf>,
    /// The unit (rig or vehicle) the records come from, for the findings table.
    #[arg(long, requires = "findings")]
    unit: Option<String>,
    /// The unit's operating hours at the validation record, for the findings table.
    #[arg(long, requires = "findings", value_parser = non_negative_hours)]
    operating_hours: Option<f64>,
}

/// Operating hours: a finite number ≥ 0.
fn non_negative_hours(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(h) if h.is_finite() && h >= 0.0 => Ok(h),
        _ => Err(format!("{s:?} is not a number of hours ≥ 0")),
    }
}

#[derive(Debug, Args)]
pub struct BlindArgs {
    /// Number of trials (kinds in blocks of ten: three physics classes, two sensor classes, two
    /// nominal, one pair, two outside every class).
    #[arg(long, default_value_t = 40)]
    trials: usize,
    /// Index of the first trial: `--first 200 --trials 100` runs trials 200–299 of the seed,
    /// the same as in a run of all of them (chunks of one campaign, see `--merge`).
    #[arg(long, default_value_t = 0)]
    first: usize,
    /// Summarise the trials of these report.json files (chunks of one seed run apart) together
    /// instead of running trials; a trial index found twice is taken once.
    #[arg(long, num_args = 1.., value_name = "REPORT_JSON", conflicts_with_all = ["first", "kind", "class", "threads", "params"])]
    merge: Vec<PathBuf>,
    /// Seed of the hidden truths (kinds, classes, forms, magnitudes, detuning) and of the sensor
    /// noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print the trials and the summary as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// Worker threads (default: the available cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Nominal parameter file given to the diagnosis (the truths detune it by up to ±20 %).
    #[arg(long, env = "DDCT_PARAMS")]
    params: Option<PathBuf>,
    /// Output directory: report.txt, report.json (trials and summary), detectability.svg.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Run only the trials of these kinds among the `--trials` (the same trials, truths and
    /// noise as in the whole run; repeat or separate by commas). Criteria of other kinds then
    /// have no trials.
    #[arg(long, value_enum, value_delimiter = ',')]
    kind: Vec<TruthKindArg>,
    /// Every trial's truth is this one class (its magnitude, form, detuning and noise drawn from
    /// the seed and the trial's index): the class's own blind trials. For a class the
    /// campaign does not draw (`sensor_speed`), or to test one class at length.
    #[arg(long, value_parser = parse_class, conflicts_with = "kind")]
    class: Option<ClassId>,
}

/// A kind of blind trial.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum TruthKindArg {
    Nominal,
    Class,
    Sensor,
    Pair,
    Outside,
}

impl From<TruthKindArg> for TruthKind {
    fn from(k: TruthKindArg) -> Self {
        match k {
            TruthKindArg::Nominal => TruthKind::Nominal,
            TruthKindArg::Class => TruthKind::Class,
            TruthKindArg::Sensor => TruthKind::Sensor,
            TruthKindArg::Pair => TruthKind::Pair,
            TruthKindArg::Outside => TruthKind::Outside,
        }
    }
}

/// A class of the diagnosis (`gap::model::class::ClassId`).
fn parse_class(s: &str) -> Result<ClassId, String> {
    ClassId::parse(s).ok_or_else(|| {
        format!(
            "unknown class `{s}` (known: {})",
            ClassId::ALL
                .iter()
                .map(|c| c.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )
    })
}

/// An effect outside every class (`truth::inject::OutsideKind`).
fn parse_outside(s: &str) -> Result<OutsideKind, String> {
    OutsideKind::parse(s).ok_or_else(|| {
        format!(
            "unknown outside effect `{s}` (known: {})",
            OutsideKind::ALL
                .iter()
                .map(|k| k.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )
    })
}

/// A form family (`truth::form::Family`).
fn parse_family(s: &str) -> Result<Family, String> {
    Family::parse(s).ok_or_else(|| {
        format!(
            "unknown family `{s}` (known: {})",
            Family::ALL
                .iter()
                .map(|f| f.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )
    })
}

#[derive(Debug, Args)]
pub struct TruthArgs {
    /// Class of the hidden effect (give it twice for a pair; neither `--class` nor `--outside`:
    /// a nominal truth).
    #[arg(long, value_parser = parse_class, num_args = 1, action = clap::ArgAction::Append)]
    class: Vec<ClassId>,
    /// An effect outside every class (judder, friction_drift, cross_clutch, engagement_time,
    /// open_drag; conduction_sign, which the blind trials do not draw), alone or beside one
    /// `--class` (its `--magnitude` then comes after the class's).
    #[arg(long, value_parser = parse_outside)]
    outside: Option<OutsideKind>,
    /// Form family of the (first) effect: spline, power, exponential, saturating,
    /// piecewise_linear, or scalar for effects without a driving variable (default: drawn).
    #[arg(long, value_parser = parse_family)]
    family: Option<Family>,
    /// Magnitude of the effect, signed, in its unit (`ddct gap truth --class C` prints the
    /// meaning, unit and range; default: drawn log-uniform over the range); give it twice for a
    /// pair, in the order of the classes.
    #[arg(long, allow_hyphen_values = true)]
    magnitude: Vec<f64>,
    /// Detune the baseline's recalibratable parameters by up to this relative error (0.2 =
    /// ±20 %, as the blind test does; default 0: the nominal parameters).
    #[arg(long, default_value_t = 0.0)]
    detune: f64,
    /// Log only x_to1_req_mm (drop the x_to2_req_mm column).
    #[arg(long)]
    only_req1: bool,
    /// The validation records start on the worn pack (friction energy carried on from the
    /// training records); diagnose them with `--carry-energy`.
    #[arg(long)]
    worn_validation: bool,
    /// Regenerate trial N of `ddct gap blind --seed S` instead (ignores the options above).
    #[arg(long)]
    trial: Option<usize>,
    /// Seed of the forms, the detuning and the sensor noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Nominal parameter file (the baseline the truth detunes).
    #[arg(long, env = "DDCT_PARAMS")]
    params: Option<PathBuf>,
    /// Output directory: train_*.csv, validate_*.csv and truth.json.
    #[arg(long)]
    out: PathBuf,
    /// Also write the records as MDF 4 bus logs, as a logger would have recorded them on the
    /// bench: train.mf4 and validate.mf4, each the records one after the other with 10 s of
    /// silence between them (the diagnosis cuts a log at such gaps).
    #[arg(long)]
    mf4: bool,
    /// With `--mf4`: the time of the first frame (seconds since the Unix epoch).
    #[arg(long, default_value_t = 1_767_225_600, requires = "mf4")]
    start_time: u64,
}

/// Silence between two records in one MF4 log of `ddct gap truth --mf4`.
const RECORD_GAP: Duration = Duration::from_secs(10);

/// The CSV records of a truth as one MF4 log at `path`, starting at `start`.
fn write_records_mf4(
    records: &[(String, String)],
    start: Duration,
    path: &Path,
) -> anyhow::Result<()> {
    let mut w = ddct::can::mf4::Mf4Writer::new();
    let mut at = start;
    for (name, csv) in records {
        let d = Dataset::from_csv(name, csv)?;
        let frames = ddct::records::record_frames::frames(&d, at, "can0")?;
        if let Some(last) = frames.last() {
            at = last.timestamp + RECORD_GAP;
        }
        for f in &frames {
            w.push(f);
        }
    }
    let f = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    w.finish(std::io::BufWriter::new(f))
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

#[derive(Debug, Args)]
pub struct ExperimentArgs {
    /// Hidden truth: `none`, or an effect id with optional parameters, e.g.
    /// `friction_pressure=0.9` or `surface_temperature_friction=0.008,0.5` (default: typical).
    #[arg(long, default_value = "none")]
    truth: String,
    /// Seed of the plant's sensor noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output directory: train_*.log and validate_*.log (candump -l format).
    #[arg(long)]
    out: PathBuf,
    /// Also write each record as CSV with the documented columns.
    #[arg(long)]
    csv: bool,
}

#[derive(Debug, Subcommand)]
pub enum GapCmd {
    /// Diagnose the gap between the nominal model and bench records: where, which effect, how far.
    Diagnose(DiagnoseArgs),
    /// Blind test: hidden truths from the independent generator, diagnosis without them, scored
    /// per class, magnitude band and form family.
    Blind(BlindArgs),
    /// Generate the records of one hidden truth of the independent generator (CSV), chosen by
    /// hand or a blind trial's.
    Truth(TruthArgs),
    /// Generate plant records (candump logs) with a truth from the effect library.
    Experiment(ExperimentArgs),
}

fn load_params(p: &Option<PathBuf>) -> anyhow::Result<Params> {
    match p {
        Some(path) => Params::load(path).with_context(|| format!("loading {}", path.display())),
        None => Ok(Params::default()),
    }
}

/// Loads the records of `files` in order: each file is checked and cut at its gaps in time into
/// segments, each segment a record of its own; the cuts and the segments left out are noted on
/// stderr (stdout may be JSON).
/// The machine's cores: the threads of the diagnosis, its file loading and the blind trials
/// when `--threads` is not given (the library reads no machine state).
fn available_cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// The training and the validation records, every file read on its own thread (decoding a
/// long candump log is a second of work); notes and the first error in the order given.
fn load_train_validate(
    train: &[PathBuf],
    validate: &[PathBuf],
) -> anyhow::Result<(Vec<Dataset>, Vec<Dataset>)> {
    load_train_validate_on(train, validate, available_cores())
}

/// [`load_train_validate`] on `threads` threads.
fn load_train_validate_on(
    train: &[PathBuf],
    validate: &[PathBuf],
    threads: usize,
) -> anyhow::Result<(Vec<Dataset>, Vec<Dataset>)> {
    let files: Vec<&PathBuf> = train.iter().chain(validate).collect();
    let loaded = ddct::par::map(threads, &files, |_, f| Segments::load(f));
    let (mut tr, mut va) = (Vec::new(), Vec::new());
    for (i, s) in loaded.into_iter().enumerate() {
        let s = s?;
        for n in s.notes() {
            eprintln!("note: {n}");
        }
        if i < train.len() { &mut tr } else { &mut va }.extend(s.datasets);
    }
    Ok((tr, va))
}

pub fn run_identify(a: IdentifyArgs) -> anyhow::Result<ExitCode> {
    let p0 = load_params(&a.params)?;
    let reference = match &a.reference {
        Some(f) => Some(Params::load(f).with_context(|| format!("reading {}", f.display()))?),
        None => None,
    };
    let (train, val) = load_train_validate(&a.train, &a.validate)?;
    let opts = IdentifyOptions {
        joint: !a.staged_only,
        split_half: !a.staged_only,
        ..IdentifyOptions::default()
    };
    let t0 = Instant::now();
    let pb = super::spinner("identifying the parameters");
    let id = identify(&train, &val, &p0, &opts);
    pb.finish_and_clear();
    let id = id?;
    let secs = t0.elapsed().as_secs_f64();
    let text = identified_file(&a, &id);
    std::fs::write(&a.out, text).with_context(|| format!("writing {}", a.out.display()))?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&id)?);
        return Ok(ExitCode::SUCCESS);
    }
    for n in &id.notes {
        println!("{n}");
    }
    println!();
    print_estimates(&id, reference.as_ref());
    print_validation(&id);
    println!("\nwrote {} ({secs:.1} s)", a.out.display());
    Ok(ExitCode::SUCCESS)
}

/// The identified parameter file: a comment naming the records, then the parameters.
fn identified_file(a: &IdentifyArgs, id: &Identification) -> String {
    format!(
        "# Identified by `ddct identify` from {} (validation: {}).\n{}",
        a.train
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        a.validate
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        id.params.to_toml_string()
    )
}

/// The estimates' table (initial, identified, 95 % interval, step), with the reference value,
/// the relative error and whether the interval holds the reference when there is one; then how
/// many identifiable parameters' final intervals hold it.
fn print_estimates(id: &Identification, reference: Option<&Params>) {
    let reference_of = |key: ParamKey| reference.map(|r| key.get(r));
    print!(
        "{:<28} {:>12} {:>12} {:>27}",
        "parameter", "initial", "identified", "95 % interval"
    );
    if reference.is_some() {
        print!(" {:>12} {:>7} {:>6}", "reference", "error", "in CI");
    }
    println!("  step");
    // The final estimate of a key is its last step's.
    let mut final_hit = std::collections::BTreeMap::new();
    for e in &id.estimates {
        print!(
            "{:<28} {:>12.4e} {:>12.4e} [{:>11.4e}, {:>11.4e}]",
            e.key, e.initial, e.value, e.ci95.0, e.ci95.1
        );
        if let Some(r) = reference_of(e.key) {
            let hit = e.ci95.0 <= r && r <= e.ci95.1;
            let err = if r != 0.0 {
                format!("{:+.1}%", 100.0 * (e.value - r) / r.abs())
            } else {
                format!("{:+.1e}", e.value)
            };
            if e.identifiable {
                final_hit.insert(e.key, hit);
            }
            print!(" {r:>12.4e} {err:>7} {:>6}", if hit { "yes" } else { "no" });
        }
        println!(
            "  {}{}",
            e.step,
            if e.identifiable {
                ""
            } else {
                " (not identifiable)"
            }
        );
    }
    if !final_hit.is_empty() {
        println!(
            "reference inside the final 95 % interval: {} of {} identifiable parameters",
            final_hit.values().filter(|h| **h).count(),
            final_hit.len()
        );
    }
}

/// The validation fits (RMSE and fit % per file, output and mode), when there are any.
fn print_validation(id: &Identification) {
    if !id.validation.is_empty() {
        println!(
            "\nvalidation fit % = 100·(1 − NRMSE) (n/a: output not excited by the experiment):"
        );
        println!(
            "{:<22} {:<10} {:<16} {:>10} {:>8}",
            "file", "output", "mode", "RMSE", "fit %"
        );
        for f in &id.validation {
            println!(
                "{:<22} {:<10} {:<16} {:>10.4} {:>8}",
                Path::new(&f.file)
                    .file_name()
                    .map(|s| s.to_string_lossy().to_string())
                    .unwrap_or_default(),
                f.output,
                f.mode,
                f.rmse,
                if f.fit_pct.is_finite() {
                    format!("{:.2}", f.fit_pct)
                } else {
                    "n/a".to_string()
                }
            );
        }
    }
}

fn run_diagnose(a: DiagnoseArgs) -> anyhow::Result<ExitCode> {
    let outcome = diagnose_and_report(&a);
    let Some(path) = &a.findings else {
        return outcome.map(|_| ExitCode::SUCCESS);
    };
    let joined = |files: &[PathBuf]| {
        files
            .iter()
            .map(|f| f.display().to_string())
            .collect::<Vec<_>>()
            .join(";")
    };
    let info = findings_table::RunInfo {
        unit: a.unit.clone(),
        log: joined(&a.validate),
        train: joined(&a.train),
        start: a.validate.first().and_then(|f| logfile::start_time(f)),
        operating_hours: a.operating_hours,
        params_hash: load_params(&a.params)
            .map(|p| findings_table::params_hash(&p))
            .unwrap_or_default(),
    };
    let rows = match &outcome {
        Ok(d) => findings_table::rows(d),
        Err(e) => vec![findings_table::error_row(&format!("{e:#}"))],
    };
    let batch = findings_table::batch(&info, &rows)
        .with_context(|| format!("{}: the findings' record batch", path.display()))?;
    let n = ddct::parquet_file::append(path, "findings", batch)?;
    eprintln!(
        "{}: {} row(s) appended, {n} in the table",
        path.display(),
        rows.len()
    );
    outcome.map(|_| ExitCode::SUCCESS)
}

/// The diagnosis of `ddct gap diagnose`, written to `--out` and printed.
fn diagnose_and_report(a: &DiagnoseArgs) -> anyhow::Result<Diagnosis> {
    let t0 = Instant::now();
    let p = load_params(&a.params)?;
    let threads = a.threads.map_or_else(available_cores, usize::from);
    let (train, val) = load_train_validate_on(&a.train, &a.validate, threads)?;
    let t_load = t0.elapsed().as_secs_f64();
    let opts = DiagnoseOptions {
        carry_energy: a.carry_energy,
        bootstrap: a.bootstrap,
        seed: a.seed,
        threads,
        excluded: a.exclude_class.clone(),
        ..DiagnoseOptions::default()
    };
    let pb = super::spinner("diagnosing: recalibration, class fits, selection");
    let d = diagnose(&train, &val, &p, &opts);
    pb.finish_and_clear();
    let d = d?;
    let t_all = t0.elapsed().as_secs_f64();
    let json = write_diagnosis(a, &d, t_all, t_load)?;
    if a.json {
        println!("{json}");
        return Ok(d);
    }
    print_diagnosis(&d);
    println!(
        "wrote {} in {t_all:.1} s",
        a.out.join("report.md").display()
    );
    Ok(d)
}

/// Writes the diagnosis into `--out`: report.json, report.md (with how long it took), the plots
/// and, when there is one, the calibration (params.toml, effects.toml and, from a template,
/// tcu.toml); returns the JSON report.
fn write_diagnosis(
    a: &DiagnoseArgs,
    d: &Diagnosis,
    t_all: f64,
    t_load: f64,
) -> anyhow::Result<String> {
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let write = |name: &str, text: &str| -> anyhow::Result<()> {
        let path = a.out.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
    };
    let json = render::json(d);
    write("report.json", &json)?;
    let mut md = render::markdown(d);
    md.push_str(&format!(
        "\nDiagnosed in {t_all:.1} s (loading {t_load:.1} s) by `ddct gap diagnose`.\n"
    ));
    write("report.md", &md)?;
    for (name, svg) in render::plots(d) {
        write(&name, &svg)?;
    }
    if let Some((params, effects)) = render::calibration(d) {
        write("params.toml", &params)?;
        write("effects.toml", &effects)?;
        if let Some(text) = tcu_template(a)? {
            write(
                "tcu.toml",
                &render::tcu_calibration(&text, "params.toml", "effects.toml"),
            )?;
        }
    }
    Ok(json)
}

/// The text of the TCU calibration to rewrite for the diagnosed calibration: `--tcu-template`,
/// else config/tcu.toml when it exists (`None`: neither).
fn tcu_template(a: &DiagnoseArgs) -> anyhow::Result<Option<String>> {
    let template = a
        .tcu_template
        .clone()
        .or_else(|| Some(PathBuf::from("config/tcu.toml")).filter(|p| p.exists()));
    template
        .map(|t| std::fs::read_to_string(&t).with_context(|| format!("reading {}", t.display())))
        .transpose()
}

/// The diagnosis in a few lines: the verdict, the five best-ranked effects, how far the gap
/// closes.
fn print_diagnosis(d: &Diagnosis) {
    let v = &d.verdict;
    println!(
        "verdict: effect {} (subsystem {})",
        v.effect,
        v.subsystem_name()
    );
    println!("  {}", v.explanation);
    if !v.ambiguous_with.is_empty() {
        println!("  ambiguous with: {}", v.ambiguous_list());
    }
    if !v.outside_library_depends_on.is_empty() {
        println!(
            "  outside the library, depends on: {}",
            v.outside_library_depends_on.join(", ")
        );
    }
    println!("ranking (validation score, 1 = sensor noise):");
    for r in v.ranking.iter().take(5) {
        println!(
            "  {:<24} {:>8.4}  ΔBIC {:>10.1}  gap explained {:>6.1} %  {}",
            r.effect,
            r.validation_score,
            r.delta_bic,
            r.gap_explained_pct,
            if r.credited { "credited" } else { "" }
        );
    }
    let h = &d.how_far;
    println!(
        "how far: {} RMSE {:.4} → {:.4} ({:.1} % reduction, 95 % CI {:.1}…{:.1} %)",
        h.output,
        h.rmse_before,
        h.rmse_after,
        h.reduction_pct,
        h.reduction_ci95.0,
        h.reduction_ci95.1
    );
}

fn run_blind(a: BlindArgs) -> anyhow::Result<ExitCode> {
    if !a.merge.is_empty() {
        return merge_blind(&a);
    }
    if a.trials == 0 {
        bail!("--trials must be at least 1");
    }
    let p = load_params(&a.params)?;
    let threads = a.threads.unwrap_or_else(available_cores).clamp(1, 64);
    let started = Instant::now();
    let correct = std::sync::atomic::AtomicUsize::new(0);
    let kinds: Vec<TruthKind> = a.kind.iter().map(|k| (*k).into()).collect();
    let indices = blind::indices(a.seed, a.first, a.trials, &kinds);
    if indices.is_empty() {
        bail!(
            "no trial of the kinds {:?} among the {} trials from {}",
            a.kind,
            a.trials,
            a.first
        );
    }
    let pb = super::bar(indices.len() as u64, "trials");
    let draw = match a.class {
        Some(c) => blind::Draw::Class(truth::Injected::new(c).map_err(anyhow::Error::msg)?),
        None => blind::Draw::Campaign,
    };
    let results = blind::run(a.seed, &indices, threads, &p, draw, &|r: &TrialResult| {
        let c = correct.fetch_add(usize::from(r.correct), std::sync::atomic::Ordering::Relaxed)
            + usize::from(r.correct);
        pb.inc(1);
        pb.set_message(format!(", {c} correct"));
    });
    pb.finish_and_clear();
    let trials = results
        .iter()
        .map(serde_json::to_value)
        .collect::<Result<Vec<_>, _>>()?;
    let mut extra = serde_json::json!({ "threads": threads, "first": a.first });
    if let Some(c) = a.class {
        // Only a run of one class says so: a campaign's report stays as it was.
        extra["class"] = c.as_str().into();
    }
    let run = BlindRun {
        seed: a.seed,
        seconds: started.elapsed().as_secs_f64(),
        how: format!("on {threads} thread(s)"),
        extra,
    };
    write_blind(&a, &run, trials)
}

/// How a blind report's trials were run.
struct BlindRun {
    seed: u64,
    seconds: f64,
    how: String,
    /// More top-level fields of report.json.
    extra: serde_json::Value,
}

/// `--merge`: the trials of several report.json files (chunks of one seed run apart, e.g. by
/// `ddct-fleet blind` on a Dask cluster) summarised together, as one run of them would be.
fn merge_blind(a: &BlindArgs) -> anyhow::Result<ExitCode> {
    let mut seed = None;
    let mut seconds = 0.0;
    let mut by_index = std::collections::BTreeMap::new();
    for file in &a.merge {
        let text =
            std::fs::read_to_string(file).with_context(|| format!("reading {}", file.display()))?;
        let v: serde_json::Value = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a blind report (JSON)", file.display()))?;
        let s = v["seed"]
            .as_u64()
            .with_context(|| format!("{}: no \"seed\"", file.display()))?;
        if *seed.get_or_insert(s) != s {
            bail!(
                "{}: seed {s}, the other reports have {}: trials of different seeds do not merge",
                file.display(),
                seed.unwrap_or(s)
            );
        }
        seconds += v["seconds"].as_f64().unwrap_or(0.0);
        let trials = v["trials"]
            .as_array()
            .with_context(|| format!("{}: no \"trials\" array", file.display()))?;
        for (k, t) in trials.iter().enumerate() {
            let scored = blind::Scored::from_json(t)
                .with_context(|| format!("{}: trial {k} is not a scored trial", file.display()))?;
            by_index.entry(scored.index).or_insert_with(|| t.clone());
        }
    }
    let run = BlindRun {
        seed: seed.unwrap_or(a.seed),
        seconds,
        how: format!("merged from {} report(s)", a.merge.len()),
        extra: serde_json::json!({
            "merged_from": a.merge.iter().map(|f| f.display().to_string()).collect::<Vec<_>>(),
        }),
    };
    write_blind(a, &run, by_index.into_values().collect())
}

/// Summarises `trials` (report.json's array) and writes the text, JSON and figure.
fn write_blind(
    a: &BlindArgs,
    run: &BlindRun,
    trials: Vec<serde_json::Value>,
) -> anyhow::Result<ExitCode> {
    let scored = trials
        .iter()
        .map(blind::Scored::from_json)
        .collect::<Result<Vec<_>, _>>()?;
    let summary = blind::summarize(&scored);
    let mut text = blind::render_text(&scored, &summary);
    text.push_str(&format!(
        "{} trials in {:.0} s {}, seed {}\n",
        scored.len(),
        run.seconds,
        run.how,
        run.seed
    ));
    let mut json = serde_json::json!({
        "seed": run.seed,
        "trials": trials,
        "summary": summary,
        "seconds": run.seconds,
        "skipped_classes": truth::inject::skipped_classes()
            .iter()
            .map(|(c, why)| serde_json::json!({"class": c, "reason": why}))
            .collect::<Vec<_>>(),
    });
    if let (Some(o), Some(extra)) = (json.as_object_mut(), run.extra.as_object()) {
        o.extend(extra.clone());
    }
    let json = serde_json::to_string_pretty(&json)?;
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        for (name, body) in [
            ("report.txt", text.clone()),
            ("report.json", json.clone()),
            ("detectability.svg", blind::detectability_svg(&summary)),
        ] {
            let path = dir.join(name);
            std::fs::write(&path, body).with_context(|| format!("writing {}", path.display()))?;
        }
    }
    if a.json {
        println!("{json}");
    } else {
        print!("{text}");
        if let Some(dir) = &a.out {
            println!("wrote {}", dir.display());
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn run_truth(a: TruthArgs) -> anyhow::Result<ExitCode> {
    let p = load_params(&a.params)?;
    let t = match a.trial {
        Some(i) => truth::draw(a.seed, i, &p),
        None => build_truth(&a, &p)?,
    };
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let pb = super::spinner("simulating the truth's rig records");
    let recs = truth::records(&t, a.seed);
    pb.finish_and_clear();
    let mut names = (Vec::new(), Vec::new());
    for (set, list) in [(&recs.train, &mut names.0), (&recs.validate, &mut names.1)] {
        for (name, csv) in set {
            let path = a.out.join(name);
            std::fs::write(&path, csv).with_context(|| format!("writing {}", path.display()))?;
            list.push(path.display().to_string());
        }
    }
    if a.mf4 {
        let start = Duration::from_secs(a.start_time);
        write_records_mf4(&recs.train, start, &a.out.join("train.mf4"))?;
        write_records_mf4(
            &recs.validate,
            start + Duration::from_secs(3600),
            &a.out.join("validate.mf4"),
        )?;
    }
    let path = a.out.join("truth.json");
    // The effects' terms over their variables: what a magnitude stated over another range is
    // read off (docs/gap.md, "Magnitudes").
    let mut json = serde_json::to_value(&t)?;
    json["curves"] = serde_json::to_value(
        t.effects
            .iter()
            .filter_map(truth::curve::curve)
            .collect::<Vec<_>>(),
    )?;
    std::fs::write(&path, serde_json::to_string_pretty(&json)?)
        .with_context(|| format!("writing {}", path.display()))?;
    print_truth(&t);
    println!(
        "wrote {} and truth.json; diagnose with:\n  ddct gap diagnose --train {} --validate {}{} --out DIR",
        a.out.display(),
        names.0.join(" "),
        names.1.join(" "),
        if t.variants.worn_validation {
            " --carry-energy"
        } else {
            ""
        }
    );
    Ok(ExitCode::SUCCESS)
}

/// The truth the options describe (one or two classes or outside forms, their family,
/// magnitudes and variants, the baseline's detuning), refused when they do not fit together.
fn build_truth(a: &TruthArgs, p: &Params) -> anyhow::Result<Truth> {
    let mut targets: Vec<Target> = a.class.iter().map(|c| Target::Class(*c)).collect();
    targets.extend(a.outside.map(Target::Outside));
    if targets.len() > 2 {
        bail!("at most two classes");
    }
    if a.magnitude.len() > targets.len() {
        bail!(
            "{} --magnitude for {} effect(s)",
            a.magnitude.len(),
            targets.len()
        );
    }
    if !(0.0..1.0).contains(&a.detune) {
        bail!("--detune must lie in 0 ≤ r < 1");
    }
    let spec = CaseSpec {
        targets,
        family: a.family,
        magnitudes: a.magnitude.clone(),
        detune: a.detune,
        variants: Variants {
            only_req1: a.only_req1,
            worn_validation: a.worn_validation,
        },
        seed: a.seed,
    };
    truth::build(&spec, p).map_err(anyhow::Error::msg)
}

/// What the truth is: its label and kind, description, each effect's magnitude range, its
/// effect size over the noise and the baseline's detuning.
fn print_truth(t: &Truth) {
    println!("truth: {} ({})", t.label(), t.kind);
    println!("  {}", t.description);
    for e in &t.effects {
        let r = truth::inject::range(e.target);
        println!(
            "  {}: magnitude range {}…{} {}{}",
            e.target,
            r.lo,
            r.hi,
            r.unit,
            if r.signed { " (either sign)" } else { "" }
        );
    }
    println!(
        "  effect size over the noise {:.2} ({}), band {}; raw (against the truth's own \
         baseline, before the closest baseline within ±20 % is refitted) {:.2}",
        t.effect_size, t.effect_channel, t.band, t.raw_effect_size
    );
    if !t.detune.is_empty() {
        println!(
            "  baseline detuned: {}",
            t.detune
                .iter()
                .map(|(k, v)| format!("{k} ×{v:.3}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
}

fn parse_truth(s: &str) -> anyhow::Result<PlantTruth> {
    if s == "none" {
        return Ok(PlantTruth::none());
    }
    let (name, vals) = match s.split_once('=') {
        Some((n, v)) => (n, Some(v)),
        None => (s, None),
    };
    let Some(id) = EffectId::parse(name) else {
        bail!(
            "unknown effect `{name}` (known: none, {})",
            EffectId::ALL.map(|e| e.as_str()).join(", ")
        );
    };
    let params: Vec<f64> = match vals {
        None => id.typical()[..id.params().len()].to_vec(),
        Some(v) => v
            .split(',')
            .map(|x| {
                x.trim()
                    .parse::<f64>()
                    .with_context(|| format!("`{x}` is not a number"))
            })
            .collect::<anyhow::Result<_>>()?,
    };
    if params.len() != id.params().len() {
        bail!(
            "{name} takes {} parameter(s) ({})",
            id.params().len(),
            id.params()
                .iter()
                .map(|p| p.name)
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    ddct::model::effects::EffectSet::single(id, &params)?;
    Ok(PlantTruth {
        effect: Some(id),
        params,
    })
}

fn run_experiment(a: ExperimentArgs) -> anyhow::Result<ExitCode> {
    let truth = parse_truth(&a.truth)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let pb = super::spinner("simulating the rig records");
    let recs = plant::experiment_records(&truth, a.seed, &Params::default());
    pb.finish_and_clear();
    for (name, records) in recs {
        let path = a.out.join(format!("{name}.log"));
        let file =
            std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?;
        let mut w = ddct::can::candump::LogWriter::new(std::io::BufWriter::new(file));
        for r in &records {
            w.write(r)?;
        }
        w.flush()?;
        if a.csv {
            let d = Dataset::from_records(&name, records.into_iter().map(Ok), 0.01)?;
            let csv = a.out.join(format!("{name}.csv"));
            std::fs::write(&csv, d.to_csv())?;
        }
        println!("wrote {}", path.display());
    }
    Ok(ExitCode::SUCCESS)
}

pub fn run(cmd: GapCmd) -> anyhow::Result<ExitCode> {
    keep_freed_memory();
    match cmd {
        GapCmd::Diagnose(a) => run_diagnose(a),
        GapCmd::Blind(a) => run_blind(a),
        GapCmd::Truth(a) => run_truth(a),
        GapCmd::Experiment(a) => run_experiment(a),
    }
}

/// The diagnosis's fits allocate and free series of a record's length (megabytes) thousands of
/// times: glibc's malloc would map each from the kernel and hand it back when freed, a page fault
/// per 4 KiB every time (a sixth of a diagnosis's time). Freed memory is kept for the next
/// allocation instead (mapped only above 256 MiB, the heap trimmed above 128 MiB free).
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets two of malloc's tuning parameters; it is called before any
    // thread of this command starts.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 256 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 128 << 20);
    }
}
