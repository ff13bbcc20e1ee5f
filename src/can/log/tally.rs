//! What a decode run tells about a log besides its frames ([`Tally`]): the malformed lines and
//! frames, the frames by E2E verdict and the logger's losses, for both decode loops (frame by
//! frame, and the CSV fast path of [`super::csv_threads`]), and the summary it ends with.

use super::error::DecodeError;
use crate::can::candump::LogError;
use crate::can::decode::Gap;
use crate::can::mf4::Mf4Error;
use std::collections::BTreeMap;
use std::path::Path;

/// Who watches a decode run: the frames it has read, and the lines it has for the user (a
/// malformed line named). The CLI draws a progress bar and writes the lines around it.
pub trait Progress {
    /// `n` more frames read (only when the run counts frames: standard input).
    fn frames(&self, n: u64);
    /// A line for the user (the CLI's standard error).
    fn note(&self, line: &str);
}

/// Why an item of the input is not a frame.
pub(crate) enum Unread {
    /// A malformed line or frame: named (after the input's name), counted and skipped.
    Skip(String),
    /// The logger before us lost this many frames here (candump -d's `DROPCOUNT`).
    Lost(u64),
    /// The input cannot be read further.
    Fatal(Box<dyn std::error::Error + Send + Sync>),
}

impl From<LogError> for Unread {
    fn from(e: LogError) -> Self {
        match e {
            LogError::Line { line, kind } => Unread::Skip(format!(":{line}: {kind}")),
            LogError::InputLost { frames, .. } => Unread::Lost(frames),
            other => Unread::Fatal(other.into()),
        }
    }
}

impl From<Mf4Error> for Unread {
    fn from(e: Mf4Error) -> Self {
        match e {
            Mf4Error::Frame { .. } => Unread::Skip(format!(": {e}")),
            other => Unread::Fatal(other.into()),
        }
    }
}

/// What a decode run tells about the log besides the decoded frames.
pub struct Tally<'a> {
    /// The input's name in messages (`-`: standard input).
    name: &'a Path,
    progress: &'a dyn Progress,
    /// Standard input: the progress counts frames, and the CSV goes out in small blocks.
    pub(crate) per_frame: bool,
    /// The ids selected (empty: all).
    filter: Vec<u32>,
    bad_lines: usize,
    /// Frames by E2E verdict (a handful of verdicts: a list, not a map, per frame).
    verdicts: Vec<(&'static str, usize)>,
    /// Frames the logger reported lost (DROPCOUNT lines) and not yet told to the decoder.
    pub(crate) lost_pending: u64,
    /// DROPCOUNT lines read.
    loss_lines: usize,
}

impl<'a> Tally<'a> {
    /// The tally of the input named `name`, showing itself through `progress`; `per_frame` for
    /// standard input; `filter`: the ids to decode (empty: all).
    pub fn new(
        name: &'a Path,
        progress: &'a dyn Progress,
        per_frame: bool,
        filter: Vec<u32>,
    ) -> Self {
        Tally {
            name,
            progress,
            per_frame,
            filter,
            bad_lines: 0,
            verdicts: Vec::new(),
            lost_pending: 0,
            loss_lines: 0,
        }
    }

    /// Malformed lines and frames seen.
    pub fn bad_lines(&self) -> usize {
        self.bad_lines
    }

    pub(crate) fn wanted(&self, id: u32) -> bool {
        self.filter.is_empty() || self.filter.contains(&id)
    }

    /// A line or frame that could not be read: named, counted.
    fn bad_item(&mut self, what: &str) {
        self.bad_lines += 1;
        self.progress
            .note(&format!("{}{what}", self.name.display()));
    }

    /// The record of a log item; a malformed line or frame is named, counted and skipped
    /// (`None`), any other error ends the decode naming the input.
    pub(crate) fn record<T, E: Into<Unread>>(
        &mut self,
        item: Result<T, E>,
    ) -> Result<Option<T>, DecodeError> {
        match item.map_err(Into::into) {
            Ok(r) => Ok(Some(r)),
            Err(Unread::Skip(what)) => {
                self.bad_item(&what);
                Ok(None)
            }
            Err(Unread::Lost(frames)) => {
                self.lost_pending += frames;
                self.loss_lines += 1;
                Ok(None)
            }
            Err(Unread::Fatal(source)) => Err(DecodeError::Input {
                name: self.name.display().to_string(),
                source,
            }),
        }
    }

    /// Frames read: the progress on standard input.
    pub(crate) fn frames_read(&self, n: u64) {
        if self.per_frame {
            self.progress.frames(n);
        }
    }

    pub(crate) fn verdict(&mut self, e2e: &'static str) {
        match self.verdicts.iter_mut().find(|(v, _)| *v == e2e) {
            Some((_, n)) => *n += 1,
            None => self.verdicts.push((e2e, 1)),
        }
    }

    /// The summary of the run, a line each: frames by E2E verdict, what the input said of
    /// frames missing from it, the silences `gaps` (unless `quiet`), the malformed lines;
    /// `lost`: the frames the logger reported lost.
    pub fn summary(&self, gaps: &[Gap<'_>], lost: u64, quiet: bool) -> Vec<String> {
        let by_name: BTreeMap<_, _> = self.verdicts.iter().copied().collect();
        let summary: Vec<String> = by_name.iter().map(|(k, v)| format!("{k} {v}")).collect();
        let mut lines = vec![format!("frames by E2E verdict: {}", summary.join(", "))];
        lines.extend(self.input_loss(lost, by_name.get("counter_skipped").copied()));
        for g in gaps.iter().filter(|_| !quiet) {
            lines.push(format!(
                "gap: {} silent from {:.6} to {:.6} s ({} ms)",
                g.message,
                g.from.as_secs_f64(),
                g.to.as_secs_f64(),
                (g.to - g.from).as_millis()
            ));
        }
        if self.bad_lines > 0 {
            lines.push(format!(
                "{}: {} malformed line(s) or frame(s)",
                self.name.display(),
                self.bad_lines
            ));
        }
        lines
    }

    /// What the input itself says of frames missing from it: the logger's DROPCOUNT lines (the
    /// counter gaps they explain are `missing_input`, not the bus's), or, reading a pipe without
    /// them, that a reader falling behind loses frames too and how to have candump say so.
    fn input_loss(&self, lost: u64, skipped: Option<usize>) -> Option<String> {
        if self.loss_lines > 0 {
            Some(format!(
                "input: the logger lost {lost} frame(s) before ddct read them ({} DROPCOUNT \
                 line(s)); the counter gaps they explain are counted as missing_input, not as \
                 the bus's E2E errors",
                self.loss_lines
            ))
        } else if self.name.as_os_str() == "-" && skipped.is_some() {
            Some(
                "input: standard input said nothing of frames it lost; a candump that falls \
                 behind loses frames too, and they show as counter_skipped here: run `candump \
                 -d` so that its DROPCOUNT lines tell its own losses from the bus's"
                    .to_string(),
            )
        } else {
            None
        }
    }
}
