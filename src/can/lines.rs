//! The lines of a byte stream read in large blocks (not a line and a `String` at a time): a log
//! of hundreds of thousands of lines is parsed straight from the block it was read into.
//!
//! A block read returns what the input has (a pipe's lines as they come), so a live stream is
//! not held back until a block is full.

use std::io::{self, Read};
use std::ops::Range;

/// Bytes asked of the input per read.
const BLOCK: usize = 256 * 1024;

/// Lines of `R`, each with its `\n` (a last line without one as it is) and its number from 1.
pub(crate) struct BlockLines<R> {
    input: R,
    buf: Vec<u8>,
    /// The unread data: `buf[start..end]`.
    start: usize,
    end: usize,
    /// `buf[start..searched]` holds no `\n` (the search goes on from there after a read).
    searched: usize,
    eof: bool,
    line_no: usize,
}

impl<R: Read> BlockLines<R> {
    pub fn new(input: R) -> Self {
        Self {
            input,
            buf: vec![0; BLOCK],
            start: 0,
            end: 0,
            searched: 0,
            eof: false,
            line_no: 0,
        }
    }

    /// Where the next line is in [`BlockLines::get`] and its number; `None` at the end of the
    /// input. The range is valid until the next call.
    pub fn next_line(&mut self) -> io::Result<Option<(usize, Range<usize>)>> {
        loop {
            let end = match memchr::memchr(b'\n', &self.buf[self.searched..self.end]) {
                Some(pos) => self.searched + pos + 1,
                None if self.eof && self.start < self.end => self.end,
                None if self.eof => return Ok(None),
                None => {
                    self.searched = self.end;
                    self.fill()?;
                    continue;
                }
            };
            let line = self.start..end;
            self.start = end;
            self.searched = end;
            self.line_no += 1;
            return Ok(Some((self.line_no, line)));
        }
    }

    /// The bytes of a line [`BlockLines::next_line`] returned.
    pub fn get(&self, line: Range<usize>) -> &[u8] {
        &self.buf[line]
    }

    /// Reads what the input has after the unread data; first moves the unread data to the front
    /// of the buffer when little room is left after it, and doubles the buffer when one line
    /// fills it.
    fn fill(&mut self) -> io::Result<()> {
        if self.buf.len() - self.end < BLOCK / 2 && self.start > 0 {
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.searched -= self.start;
            self.start = 0;
        }
        if self.end == self.buf.len() {
            self.buf.resize(2 * self.buf.len(), 0);
        }
        loop {
            match self.input.read(&mut self.buf[self.end..]) {
                Ok(0) => self.eof = true,
                Ok(n) => self.end += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            }
            return Ok(());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lines_of(input: impl Read) -> Vec<(usize, Vec<u8>)> {
        let mut lines = BlockLines::new(input);
        let mut out = Vec::new();
        while let Some((no, r)) = lines.next_line().unwrap() {
            out.push((no, lines.get(r).to_vec()));
        }
        out
    }

    #[test]
    fn lines_keep_their_ends_and_numbers() {
        let got = lines_of(&b"a\n\nbc\r\nlast"[..]);
        let want: Vec<(usize, Vec<u8>)> = vec![
            (1, b"a\n".to_vec()),
            (2, b"\n".to_vec()),
            (3, b"bc\r\n".to_vec()),
            (4, b"last".to_vec()),
        ];
        assert_eq!(got, want);
        assert!(lines_of(&b""[..]).is_empty());
        assert_eq!(lines_of(&b"x\n"[..]), vec![(1, b"x\n".to_vec())]);
    }

    /// Hands out its data a few bytes per read, as a pipe may.
    struct Trickle<'a>(&'a [u8]);
    impl Read for Trickle<'_> {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            let n = buf.len().min(self.0.len()).min(3);
            buf[..n].copy_from_slice(&self.0[..n]);
            self.0 = &self.0[n..];
            Ok(n)
        }
    }

    #[test]
    fn lines_across_reads_and_longer_than_a_block() {
        let long = "y".repeat(3 * BLOCK + 5);
        let text = format!("one\ntwo\n{long}\nend");
        let got = lines_of(Trickle(text.as_bytes()));
        assert_eq!(got.len(), 4);
        assert_eq!(got[1], (2, b"two\n".to_vec()));
        assert_eq!(got[2].1.len(), long.len() + 1);
        assert_eq!(got[3], (4, b"end".to_vec()));
        assert_eq!(lines_of(text.as_bytes()), got);
    }
}
