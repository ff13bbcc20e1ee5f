//! What `ddct log decode` tells about a log besides its frames ([`Decoding`]): the malformed
//! lines and frames, the frames by E2E verdict and the logger's losses, for both decode loops
//! (frame by frame, and the CSV fast path of `super::csv`).

use anyhow::Context;
use ddct::can::candump::LogError;
use ddct::can::mf4::Mf4Error;
use indicatif::ProgressBar;

/// Why an item of the input is not a frame.
pub(super) enum Unread {
    /// A malformed line or frame: named (after the file name), counted and skipped.
    Skip(String),
    /// The logger before us lost this many frames here (candump -d's `DROPCOUNT`).
    Lost(u64),
    /// The input cannot be read further.
    Fatal(anyhow::Error),
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

/// What `ddct log decode` tells about the log besides the decoded frames.
pub(super) struct Decoding<'a> {
    pub(super) file: &'a std::path::Path,
    pub(super) pb: ProgressBar,
    /// Standard input: the progress counts frames.
    pub(super) per_frame: bool,
    /// The ids `-m` selects (empty: all).
    pub(super) filter: Vec<u32>,
    pub(super) bad_lines: usize,
    /// Frames by E2E verdict (a handful of verdicts: a list, not a map, per frame).
    pub(super) verdicts: Vec<(&'static str, usize)>,
    /// Frames the logger reported lost (DROPCOUNT lines) and not yet told to the decoder.
    pub(super) lost_pending: u64,
    /// DROPCOUNT lines read.
    pub(super) loss_lines: usize,
}

impl Decoding<'_> {
    pub(super) fn wanted(&self, id: u32) -> bool {
        self.filter.is_empty() || self.filter.contains(&id)
    }

    /// A line or frame that could not be read: named on stderr, counted.
    pub(super) fn bad_item(&mut self, what: &str) {
        self.bad_lines += 1;
        self.pb
            .suspend(|| eprintln!("{}{what}", self.file.display()));
    }

    /// The record of a log item; a malformed line or frame is named, counted and skipped
    /// (`None`), any other error ends the decode naming the file.
    pub(super) fn record<T, E: Into<Unread>>(
        &mut self,
        item: Result<T, E>,
    ) -> anyhow::Result<Option<T>> {
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
            Err(Unread::Fatal(e)) => Err(e).with_context(|| format!("{}", self.file.display())),
        }
    }

    /// Frames read: the progress on standard input.
    pub(super) fn frames_read(&self, n: u64) {
        if self.per_frame {
            self.pb.inc(n);
        }
    }

    pub(super) fn verdict(&mut self, e2e: &'static str) {
        match self.verdicts.iter_mut().find(|(v, _)| *v == e2e) {
            Some((_, n)) => *n += 1,
            None => self.verdicts.push((e2e, 1)),
        }
    }
}
