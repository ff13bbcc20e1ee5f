//! What can be wrong with an MDF file, for the reader and the writer alike.

use thiserror::Error;

/// What is wrong with an MDF file.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum Mf4Error {
    #[error("not an MDF file (it does not start with \"MDF     \")")]
    NotMdf,
    #[error("MDF version {0}: only MDF 4.x is read")]
    Version(u16),
    #[error("the file is not finalized (unfinalized flags 0x{0:04X}, custom 0x{1:04X}); finalize it with the logger's tool first")]
    Unfinalized(u16, u16),
    #[error("link to offset {at} points outside the file")]
    Link { at: u64 },
    #[error("no block at offset {at} (no \"##\")")]
    NotABlock { at: u64 },
    #[error("{kind} block at offset {at} runs past the end of the file (truncated)")]
    Truncated { kind: String, at: u64 },
    #[error("block at offset {at}: expected ##{expected}, found ##{found}")]
    WrongBlock {
        at: u64,
        expected: String,
        found: String,
    },
    #[error("{kind} block: {need} bytes of data needed, it has {have}")]
    ShortBlock {
        kind: String,
        need: usize,
        have: usize,
    },
    #[error("data block at offset {at}: deflate data is corrupt")]
    Inflate { at: u64 },
    #[error("channel group {group} ({name}): {what}")]
    Channel {
        group: usize,
        name: String,
        what: String,
    },
    #[error("data group at offset {at}: record id {id} belongs to no channel group")]
    RecordId { at: u64, id: u64 },
    #[error("data group at offset {at}: the data ends inside a record")]
    PartialRecord { at: u64 },
    #[error("unsupported: {0}")]
    Unsupported(String),
    #[error("frame {index}: {what}")]
    Frame { index: usize, what: String },
    #[error(transparent)]
    Io(#[from] crate::io_error::IoError),
}
