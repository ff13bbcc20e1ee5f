//! `ddct log stats`: the cycle-time statistics of a log's messages
//! ([`crate::can::decode::cycle_stats`]) as a table or a JSON array.

use crate::can::decode::CycleStats;
use serde_json::json;
use std::fmt::Write as _;

/// One line per message under a header, each ending with a newline.
pub fn table(stats: &[CycleStats]) -> String {
    let mut out = format!(
        "{:<6} {:<14} {:>7} {:>7} {:>8} {:>8} {:>8} {:>8}\n",
        "id", "message", "frames", "nominal", "p50 ms", "p99 ms", "min ms", "max ms"
    );
    for s in stats {
        let _ = writeln!(
            out,
            "0x{:03X}  {:<14} {:>7} {:>7} {:>8.3} {:>8.3} {:>8.3} {:>8.3}",
            s.id,
            s.name.unwrap_or("?"),
            s.frames,
            s.nominal_ms.map_or("-".to_string(), |m| format!("{m} ms")),
            s.p50_ms,
            s.p99_ms,
            s.min_ms,
            s.max_ms
        );
    }
    out
}

/// A JSON array, an object per message (no newline at the end).
pub fn json(stats: &[CycleStats]) -> String {
    let arr: Vec<_> = stats
        .iter()
        .map(|s| {
            json!({"id": s.id, "name": s.name, "nominal_ms": s.nominal_ms, "frames": s.frames,
                   "mean_ms": s.mean_ms, "p50_ms": s.p50_ms, "p99_ms": s.p99_ms,
                   "min_ms": s.min_ms, "max_ms": s.max_ms})
        })
        .collect();
    serde_json::Value::Array(arr).to_string()
}
