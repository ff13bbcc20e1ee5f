//! ASAM MDF 4 bus-logging files (`.mf4`) with classic CAN frames: what CANedge loggers and
//! asammdf write and read (ASAM MDF 4.1 with the ASAM "Bus Logging" channel conventions).
//!
//! A frame is a record of a channel group flagged as bus events, with an acquisition source of
//! bus type CAN, a time master channel and a `CAN_DataFrame` byte-array channel whose
//! composition holds the members `CAN_DataFrame.BusChannel`, `.ID` (29 bits; bit 31 the IDE
//! flag in some loggers), `.IDE`, `.DLC`, `.DataLength`, `.DataBytes` and optionally `.Dir`;
//! remote frames likewise as `CAN_RemoteFrame`. [`read`] finds every such group in any data
//! group (sorted or unsorted, `DT`, `DL`, `HL` and deflate-compressed `DZ` data blocks) and
//! gives the frames in time order; [`Mf4Writer`] writes one sorted data group per interface
//! and frame kind, in the layout of [`layout`].
//!
//! Why our own code and not the `mdf4-rs` crate: its repository is archived, its releases need
//! a newer Rust than this project's 1.85, it keeps every frame as a 64-byte buffer plus
//! metadata until the end, and it does not read unsorted or compressed files such as loggers
//! write. The subset here is about 700 lines; asammdf checks it both ways in
//! `tests/python/test_mf4.py`.

mod block;
pub mod layout;
mod read;
mod write;

pub use read::{read, Mf4Frames};
pub use write::Mf4Writer;

use thiserror::Error;

/// The first 8 bytes of every MDF file.
pub const MAGIC: &[u8; 8] = b"MDF     ";

/// Offset of the header's start time (ns since the epoch, u64): the HD block follows the
/// 64-byte identification block, its 24-byte header and 6 links.
pub const START_TIME_AT: usize = 64 + 24 + 6 * 8;

/// The header's start time (ns since the epoch) from the first [`START_TIME_AT`] + 8 bytes of
/// a file, if they are an MDF 4 identification block and header block.
pub fn start_time_ns(head: &[u8]) -> Option<u64> {
    let version = u16::from_le_bytes(head.get(28..30)?.try_into().ok()?);
    let hd = head.get(64..68)?;
    if !is_mdf(head) || !(400..500).contains(&version) || hd != b"##HD" {
        return None;
    }
    Some(u64::from_le_bytes(
        head.get(START_TIME_AT..START_TIME_AT + 8)?
            .try_into()
            .ok()?,
    ))
}

/// Whether `head` (the first bytes of a file) starts like an MDF file.
pub fn is_mdf(head: &[u8]) -> bool {
    head.starts_with(MAGIC)
}

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
