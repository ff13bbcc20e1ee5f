//! `ddct dbc`: show the bus contract and its sample frames.

use clap::Subcommand;
use ddct::can::e2e::sample_frames;
use ddct::can::messages::MESSAGES;
use serde_json::json;
use std::process::ExitCode;

#[derive(Debug, Subcommand)]
pub enum DbcCmd {
    /// List the messages and signals of the contract (ids, cycle times, layout, units).
    Show,
    /// Print one sample frame per message at the min, mid and max of every signal (E2E filled in).
    Samples {
        /// JSON array instead of a table.
        #[arg(long)]
        json: bool,
    },
}

pub fn run(cmd: DbcCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        DbcCmd::Show => show(),
        DbcCmd::Samples { json } => samples(json),
    }
    Ok(ExitCode::SUCCESS)
}

fn show() {
    println!(
        "{:<6} {:<14} {:>3} {:>6}  {:<7} {:<4}",
        "id", "message", "dlc", "cycle", "sender", "e2e"
    );
    for m in MESSAGES {
        println!(
            "0x{:03X}  {:<14} {:>3} {:>4}ms  {:<7} {}",
            m.id,
            m.name,
            m.dlc,
            m.cycle_ms,
            m.sender,
            if m.e2e { "yes" } else { "no" }
        );
        for s in m.signals {
            let values: Vec<String> = s.values.iter().map(|(r, l)| format!("{r}={l}")).collect();
            println!(
                "         {:<20} bits {:>2}..{:<2} {} x{} {:+} [{} .. {}] {:<6} {}",
                s.name,
                s.start_bit,
                s.start_bit + s.length - 1,
                if s.signed { "signed  " } else { "unsigned" },
                s.factor,
                s.offset,
                s.min,
                s.max,
                s.unit,
                values.join(" ")
            );
        }
    }
}

fn hex(data: &[u8]) -> String {
    data.iter().map(|b| format!("{b:02X}")).collect()
}

fn samples(as_json: bool) {
    let frames = sample_frames();
    if as_json {
        let arr: Vec<_> = frames
            .iter()
            .map(|f| {
                let signals: serde_json::Map<String, serde_json::Value> = f
                    .def
                    .signals
                    .iter()
                    .zip(&f.values)
                    .map(|(s, v)| (s.name.to_string(), json!(v)))
                    .collect();
                json!({"id": f.def.id, "name": f.def.name, "case": f.case.as_str(), "signals": signals, "data": hex(&f.data)})
            })
            .collect();
        println!("{}", serde_json::Value::Array(arr));
    } else {
        for f in &frames {
            println!(
                "{:03X}#{}  {:<14} {}",
                f.def.id,
                hex(&f.data),
                f.def.name,
                f.case.as_str()
            );
        }
    }
}
