//! A decode run: a log (candump text, candump's screen output or MDF 4) decoded frame by frame
//! with the built-in contract or a DBC file ([`AnyDecoder`]) and written in a [`Format`], what
//! the log itself said counted in a [`Tally`]. The caller opens the input and the outputs.

use super::csv_threads::csv_builtin;
use super::error::{DecodeError, UnknownMessage};
use super::shown::{AnyDecoder, Shown};
use super::sink::{json_line, push_parquet, table_line, write_csv, Format};
use super::tally::{Tally, Unread};
use crate::can::candump::{LogReader, LogRecord};
use crate::can::columnar::SignalWriter;
use crate::can::decode_csv::{CsvRows, CSV_HEADER};
use crate::can::messages::{message_by_name, message_def};
use crate::can::mf4::Mf4Frames;
use crate::can::runtime_dbc::RuntimeDbc;
use std::io::{Read, Write};

/// The log a run decodes: text read line by line, or an MDF file's frames.
pub enum LogInput<R> {
    Text(LogReader<R>),
    Mf4(Mf4Frames),
}

/// The ids `-m/--message` selects: names or hex ids of the built-in contract, or of `dbc`
/// when one is given.
pub fn message_ids(
    messages: &[String],
    dbc: Option<&RuntimeDbc>,
) -> Result<Vec<u32>, UnknownMessage> {
    messages
        .iter()
        .map(|m| {
            let t = m.trim_start_matches("0x").trim_start_matches("0X");
            let id = u32::from_str_radix(t, 16).ok();
            let found = match dbc {
                Some(db) => db
                    .message_by_name(m)
                    .map(|d| d.id)
                    .or(id.filter(|id| db.messages.iter().any(|d| d.id == *id))),
                None => message_by_name(m)
                    .map(|def| u32::from(def.id))
                    .or(id.filter(|id| message_def(*id).is_some())),
            };
            found.ok_or_else(|| UnknownMessage {
                name: m.clone(),
                of: dbc.map_or("the contract".to_string(), |db| {
                    db.path.display().to_string()
                }),
            })
        })
        .collect()
}

/// Decodes `input` with `decoder` into `out` (the text formats) or `parquet` (which
/// [`Format::Parquet`] needs), counting in `tally` what the log said besides its frames. The
/// built-in decoder's CSV of a text log goes through two threads (reading and decoding, writing).
pub fn decode<R: Read, W: Write + Send>(
    input: LogInput<R>,
    decoder: &mut AnyDecoder<'_>,
    format: Format,
    tally: &mut Tally<'_>,
    out: &mut (impl Write + Send),
    parquet: Option<&mut SignalWriter<W>>,
) -> Result<(), DecodeError> {
    match (decoder, format, input) {
        (AnyDecoder::Builtin(dec), Format::Csv, LogInput::Text(mut reader)) => {
            csv_builtin(&mut reader, dec, tally, out)
        }
        (dec, _, LogInput::Mf4(frames)) => frame_by_frame(frames, dec, format, tally, out, parquet),
        (dec, _, LogInput::Text(mut reader)) => {
            frame_by_frame(reader.by_ref(), dec, format, tally, out, parquet)
        }
    }
}

/// Every other format and the `--dbc` decoder: each frame decoded into a [`Shown`] and written
/// as the format asks.
fn frame_by_frame<E: Into<Unread>, W: Write + Send>(
    items: impl Iterator<Item = Result<LogRecord, E>>,
    decoder: &mut AnyDecoder<'_>,
    format: Format,
    run: &mut Tally<'_>,
    out: &mut impl Write,
    mut parquet: Option<&mut SignalWriter<W>>,
) -> Result<(), DecodeError> {
    let mut rows = CsvRows::new();
    if format == Format::Csv {
        out.write_all(CSV_HEADER.as_bytes())?;
    }
    for item in items {
        let Some(rec) = run.record(item)? else {
            continue;
        };
        decoder.input_lost(std::mem::take(&mut run.lost_pending));
        run.frames_read(1);
        // Every frame goes through the decoder (its E2E and gap tracking); only the selected
        // ones are turned into output.
        let wanted = run.wanted(rec.frame.raw_id());
        let table = format == Format::Table;
        let builtin;
        let runtime_decoded;
        let d = match decoder {
            AnyDecoder::Builtin(dec) => {
                builtin = dec.decode(&rec);
                if !wanted {
                    continue;
                }
                Shown::builtin(&builtin, table)
            }
            AnyDecoder::Runtime(dec) => {
                runtime_decoded = dec.decode(&rec);
                if !wanted {
                    continue;
                }
                Shown::runtime(&rec, &runtime_decoded, table)
            }
        };
        run.verdict(d.e2e);
        match format {
            Format::Table => writeln!(out, "{}", table_line(&d))?,
            Format::Csv => write_csv(out, &mut rows, &d)?,
            Format::Json => writeln!(out, "{}", json_line(&d))?,
            Format::Parquet => {
                if let Some(w) = parquet.as_deref_mut() {
                    push_parquet(w, &d)?;
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::candump::{LogRecord, LogWriter};
    use crate::can::decode::LogDecoder;
    use crate::can::e2e::E2eSender;
    use crate::can::messages::{ids, EngStatus};
    use crate::can::CanFrame;
    use std::cell::RefCell;
    use std::path::Path;
    use std::time::Duration;

    /// Notes kept, frames counted.
    #[derive(Default)]
    struct Kept(RefCell<Vec<String>>);

    impl super::super::tally::Progress for Kept {
        fn frames(&self, _n: u64) {}
        fn note(&self, line: &str) {
            self.0.borrow_mut().push(line.to_string());
        }
    }

    /// A candump log of ENG_Status frames (a repeated counter every seventh) and frames of
    /// no message, with a malformed line in the middle.
    fn log_text() -> String {
        let mut tx = E2eSender::new();
        let mut w = LogWriter::new(Vec::new());
        for k in 0..3000u64 {
            let mut d = EngStatus {
                eng_speed: 800.0 + k as f64,
                ..Default::default()
            }
            .encode()
            .unwrap();
            if k % 7 != 0 {
                tx.protect(ids::ENG_STATUS, &mut d);
            }
            let r = LogRecord {
                timestamp: Duration::from_millis(10 * k),
                iface: "vcan0".into(),
                frame: CanFrame::standard(ids::ENG_STATUS, &d).unwrap(),
                direction: None,
            };
            w.write(&r).unwrap();
            w.write_frame(
                r.timestamp,
                "vcan0",
                &CanFrame::standard(0x7FF, &[1]).unwrap(),
                None,
            )
            .unwrap();
        }
        let text = String::from_utf8(w.into_inner()).unwrap();
        let mid = text.len() / 2;
        let cut = mid + text[mid..].find('\n').unwrap() + 1;
        format!("{}not a frame\n{}", &text[..cut], &text[cut..])
    }

    fn run(text: &str, format: Format, two_threads: bool) -> (Vec<u8>, Vec<String>, usize) {
        let kept = Kept::default();
        let mut tally = Tally::new(Path::new("x.log"), &kept, false, Vec::new());
        let mut dec = AnyDecoder::Builtin(LogDecoder::default());
        let reader = LogReader::new(text.as_bytes());
        let mut out = Vec::new();
        let none: Option<&mut SignalWriter<Vec<u8>>> = None;
        if two_threads {
            decode(
                LogInput::Text(reader),
                &mut dec,
                format,
                &mut tally,
                &mut out,
                none,
            )
            .unwrap();
        } else {
            frame_by_frame(reader, &mut dec, format, &mut tally, &mut out, none).unwrap();
        }
        let (gaps, lost) = dec.gaps_and_lost();
        let summary = tally.summary(gaps, lost, false);
        let bad = tally.bad_lines();
        drop(tally);
        let mut lines = kept.0.into_inner();
        lines.extend(summary);
        (out, lines, bad)
    }

    /// The built-in decoder's CSV on two threads writes what the frame-by-frame loop writes,
    /// and both tell the same: the malformed line named and counted, the verdicts.
    #[test]
    fn the_two_thread_csv_is_the_frame_by_frame_csv() {
        let text = log_text();
        let fast = run(&text, Format::Csv, true);
        let slow = run(&text, Format::Csv, false);
        assert_eq!(fast, slow);
        assert_eq!(fast.2, 1);
        assert!(fast.0.starts_with(CSV_HEADER.as_bytes()));
        assert!(fast.1[0].starts_with("x.log:"), "{:?}", fast.1);
        assert!(fast.1.iter().any(
            |l| l.starts_with("frames by E2E verdict: ") && l.contains("not_in_contract 3000")
        ));
        assert_eq!(
            fast.1.last().unwrap(),
            "x.log: 1 malformed line(s) or frame(s)"
        );
    }

    /// `-m` takes names and hex ids of the contract; anything else is refused by name.
    #[test]
    fn message_ids_take_names_and_ids_of_the_contract() {
        let ids = message_ids(&["ENG_Status".into(), "0x130".into()], None).unwrap();
        assert_eq!(ids[0], u32::from(crate::can::messages::ids::ENG_STATUS));
        assert_eq!(ids[1], 0x130);
        let e = message_ids(&["Nope".into()], None).unwrap_err();
        assert_eq!(
            e.to_string(),
            "Nope: not a message name or id of the contract"
        );
    }
}
