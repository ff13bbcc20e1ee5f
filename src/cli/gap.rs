//! `ddct identify` and `ddct gap`: parameter identification and sim-to-real diagnosis (issue 7).
//! Wiring only: load files, call `ddct::gap`, write the outputs, print summaries.

use anyhow::{bail, Context};
use clap::{Args, Subcommand};
use ddct::gap::blind::{self, TrialResult};
use ddct::gap::dataset::{Dataset, Segments};
use ddct::gap::diagnose::{diagnose, DiagnoseOptions};
use ddct::gap::identify::{identify, IdentifyOptions};
use ddct::gap::keys;
use ddct::gap::report;
use ddct::model::effects::EffectId;
use ddct::model::Params;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

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
    /// Training records from "reality" (candump `-l` logs or CSV).
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
}

#[derive(Debug, Args)]
pub struct BlindArgs {
    /// Number of trials.
    #[arg(long, default_value_t = 40)]
    trials: usize,
    /// Seed of the hidden truths and of the plant's sensor noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print the trials and the summary as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// Worker threads (default: the available cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Nominal parameter file given to the diagnosis and to the plant.
    #[arg(long, env = "DDCT_PARAMS")]
    params: Option<PathBuf>,
    /// Detune the plant's recalibratable parameters (kiss-point law, convective and heating
    /// terms, actuator lag) by up to this relative error per trial (e.g. 0.05), so that every
    /// effect has to beat plain recalibration.
    #[arg(long, default_value_t = 0.0)]
    perturb: f64,
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
    /// Blind test: hidden truths in the plant, diagnosis without them, scored.
    Blind(BlindArgs),
    /// Generate the blind test's training and validation records for a given truth.
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
fn load_all(files: &[PathBuf]) -> anyhow::Result<Vec<Dataset>> {
    let mut out = Vec::new();
    for f in files {
        let s = Segments::load(f)?;
        for n in s.notes() {
            eprintln!("note: {n}");
        }
        out.extend(s.datasets);
    }
    Ok(out)
}

pub fn run_identify(a: IdentifyArgs) -> anyhow::Result<ExitCode> {
    let p0 = load_params(&a.params)?;
    let reference = match &a.reference {
        Some(f) => Some(Params::load(f).with_context(|| format!("reading {}", f.display()))?),
        None => None,
    };
    let train = load_all(&a.train)?;
    let val = load_all(&a.validate)?;
    let opts = IdentifyOptions {
        joint: !a.staged_only,
        split_half: !a.staged_only,
        ..IdentifyOptions::default()
    };
    let t0 = Instant::now();
    let id = identify(&train, &val, &p0, &opts)?;
    let secs = t0.elapsed().as_secs_f64();
    let text = format!(
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
    );
    std::fs::write(&a.out, text).with_context(|| format!("writing {}", a.out.display()))?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&id)?);
        return Ok(ExitCode::SUCCESS);
    }
    for n in &id.notes {
        println!("{n}");
    }
    println!();
    let reference_of = |key: &str| reference.as_ref().and_then(|r| keys::get(r, key));
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
        if let Some(r) = reference_of(&e.key) {
            let hit = e.ci95.0 <= r && r <= e.ci95.1;
            let err = if r != 0.0 {
                format!("{:+.1}%", 100.0 * (e.value - r) / r.abs())
            } else {
                format!("{:+.1e}", e.value)
            };
            if e.identifiable {
                final_hit.insert(e.key.as_str(), hit);
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
    println!("\nwrote {} ({secs:.1} s)", a.out.display());
    Ok(ExitCode::SUCCESS)
}

fn run_diagnose(a: DiagnoseArgs) -> anyhow::Result<ExitCode> {
    let t0 = Instant::now();
    let p = load_params(&a.params)?;
    let train = load_all(&a.train)?;
    let val = load_all(&a.validate)?;
    let t_load = t0.elapsed().as_secs_f64();
    let opts = DiagnoseOptions {
        carry_energy: a.carry_energy,
        bootstrap: a.bootstrap,
        seed: a.seed,
        ..DiagnoseOptions::default()
    };
    let d = diagnose(&train, &val, &p, &opts)?;
    let t_all = t0.elapsed().as_secs_f64();
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let write = |name: &str, text: &str| -> anyhow::Result<()> {
        let path = a.out.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
    };
    let json = report::json(&d);
    write("report.json", &json)?;
    let mut md = report::markdown(&d);
    md.push_str(&format!(
        "\nDiagnosed in {t_all:.1} s (loading {t_load:.1} s) by `ddct gap diagnose`.\n"
    ));
    write("report.md", &md)?;
    for (name, svg) in report::plots(&d) {
        write(&name, &svg)?;
    }
    if let Some((params, effects)) = report::calibration(&d) {
        write("params.toml", &params)?;
        write("effects.toml", &effects)?;
        let template = a
            .tcu_template
            .clone()
            .or_else(|| Some(PathBuf::from("config/tcu.toml")).filter(|p| p.exists()));
        if let Some(t) = template {
            let text =
                std::fs::read_to_string(&t).with_context(|| format!("reading {}", t.display()))?;
            write(
                "tcu.toml",
                &report::tcu_calibration(&text, "params.toml", "effects.toml"),
            )?;
        }
    }
    if a.json {
        println!("{json}");
        return Ok(ExitCode::SUCCESS);
    }
    let v = &d.verdict;
    println!("verdict: effect {} (subsystem {})", v.effect, v.subsystem);
    println!("  {}", v.explanation);
    if !v.ambiguous_with.is_empty() {
        println!("  ambiguous with: {}", v.ambiguous_with.join(", "));
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
    println!(
        "wrote {} in {t_all:.1} s",
        a.out.join("report.md").display()
    );
    Ok(ExitCode::SUCCESS)
}

fn progress(done: usize, total: usize, started: Instant, correct: usize) {
    let w = 30;
    let filled = (done * w).checked_div(total).unwrap_or(w);
    let el = started.elapsed().as_secs_f64();
    let eta = if done > 0 {
        el / done as f64 * (total - done) as f64
    } else {
        f64::NAN
    };
    eprint!(
        "\r[{}{}] {done}/{total} trials, {correct} correct, {el:.0} s elapsed, ~{eta:.0} s left ",
        "=".repeat(filled),
        " ".repeat(w - filled)
    );
    let _ = std::io::stderr().flush();
}

fn run_blind(a: BlindArgs) -> anyhow::Result<ExitCode> {
    if a.trials == 0 {
        bail!("--trials must be at least 1");
    }
    let p = load_params(&a.params)?;
    let threads = a
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .clamp(1, 64);
    let opts = DiagnoseOptions::default();
    let started = Instant::now();
    let next = std::sync::atomic::AtomicUsize::new(0);
    let (tx, rx) = std::sync::mpsc::channel::<TrialResult>();
    let mut results: Vec<TrialResult> = Vec::with_capacity(a.trials);
    std::thread::scope(|s| {
        for _ in 0..threads.min(a.trials) {
            let tx = tx.clone();
            let next = &next;
            let opts = &opts;
            let p = &p;
            s.spawn(move || loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if i >= a.trials {
                    break;
                }
                if tx
                    .send(blind::run_trial(a.seed, i, p, opts, a.perturb))
                    .is_err()
                {
                    break;
                }
            });
        }
        drop(tx);
        progress(0, a.trials, started, 0);
        for r in rx {
            results.push(r);
            let correct = results.iter().filter(|r| r.correct).count();
            progress(results.len(), a.trials, started, correct);
        }
    });
    eprintln!();
    results.sort_by_key(|r| r.index);
    let summary = blind::summarize(&results);
    let secs = started.elapsed().as_secs_f64();
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "seed": a.seed,
                "trials": results,
                "summary": summary,
                "seconds": secs,
            }))?
        );
        return Ok(ExitCode::SUCCESS);
    }
    println!(
        "{:>3}  {:<31} {:<15} {:<22} {:<22} {:>4} {:>7}",
        "#", "truth", "magnitude", "verdict", "subsystem", "ok", "red. %"
    );
    for r in &results {
        let mag = r
            .truth
            .params
            .iter()
            .map(|v| format!("{v:.3e}"))
            .collect::<Vec<_>>()
            .join(",");
        println!(
            "{:>3}  {:<31} {:<15} {:<22} {:<22} {:>4} {:>7}",
            r.index,
            if r.truth.kind == "outside_library" {
                format!("{} (outside)", r.truth.effect)
            } else {
                r.truth.effect.clone()
            },
            mag,
            r.verdict_effect,
            r.verdict_subsystem,
            if r.correct { "yes" } else { "NO" },
            if r.truth.kind == "library" {
                format!("{:.1}", r.reduction_pct)
            } else {
                "".into()
            }
        );
    }
    println!("\nconfusion matrix (rows: hidden truth, columns: verdict):");
    let mut cols: Vec<String> = summary
        .confusion
        .values()
        .flat_map(|m| m.keys().cloned())
        .collect();
    cols.sort();
    cols.dedup();
    let short = |s: &str| -> String { s.chars().take(12).collect() };
    print!("{:<40}", "");
    for c in &cols {
        print!(" {:>12}", short(c));
    }
    println!();
    for (t, row) in &summary.confusion {
        print!("{t:<40}");
        for c in &cols {
            print!(" {:>12}", row.get(c).copied().unwrap_or(0));
        }
        println!();
    }
    println!();
    println!(
        "library trials: {:>3}  top-1 effect:              {:>6.1} %  (goal ≥ 90 %)",
        summary.library_trials, summary.top1_pct
    );
    println!(
        "                      subsystem named first:     {:>6.1} %  (goal ≥ 95 %, library + outside trials)",
        summary.subsystem_first_pct
    );
    println!(
        "nominal trials: {:>3}  no effect claimed:         {:>6.1} %  (goal ≥ 90 %)",
        summary.nominal_trials, summary.nominal_clean_pct
    );
    println!(
        "outside trials: {:>3}  flagged outside_library:   {:>6.1} %  (goal ≥ 80 %)",
        summary.outside_trials, summary.outside_flagged_pct
    );
    println!(
        "median validation gap reduction, correct library trials: {:.1} % RMSE ({:.1} % of the gap above noise) (goal ≥ 70 %)",
        summary.median_reduction_pct, summary.median_gap_reduction_pct
    );
    println!(
        "{} trials in {secs:.0} s on {threads} thread(s){}",
        results.len(),
        if a.perturb > 0.0 {
            format!(
                ", plant parameters detuned by up to ±{:.0} %",
                100.0 * a.perturb
            )
        } else {
            String::new()
        }
    );
    Ok(ExitCode::SUCCESS)
}

fn parse_truth(s: &str) -> anyhow::Result<blind::Truth> {
    if s == "none" {
        return Ok(blind::Truth {
            effect: "none".into(),
            kind: "none".into(),
            subsystem: "none".into(),
            params: vec![],
        });
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
    Ok(blind::Truth {
        effect: id.as_str().into(),
        kind: if id.in_library() {
            "library".into()
        } else {
            "outside_library".into()
        },
        subsystem: id.subsystem().as_str().into(),
        params,
    })
}

fn run_experiment(a: ExperimentArgs) -> anyhow::Result<ExitCode> {
    let truth = parse_truth(&a.truth)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let recs = blind::experiment_records(&truth, a.seed, &Params::default());
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
    match cmd {
        GapCmd::Diagnose(a) => run_diagnose(a),
        GapCmd::Blind(a) => run_blind(a),
        GapCmd::Experiment(a) => run_experiment(a),
    }
}
