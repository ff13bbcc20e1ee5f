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
mod error;
pub mod layout;
mod read;
mod write;

pub use block::{is_mdf, MAGIC};
pub use error::Mf4Error;
pub use read::{read, Mf4Frames};
pub use write::Mf4Writer;

/// Offset of the header's start time (ns since the epoch, u64): the HD block follows the
/// 64-byte identification block, its 24-byte header and 6 links.
pub(crate) const START_TIME_AT: usize = 64 + 24 + 6 * 8;

/// The header's start time (ns since the epoch) from the first [`START_TIME_AT`] + 8 bytes of
/// a file, if they are an MDF 4 identification block and header block.
pub(crate) fn start_time_ns(head: &[u8]) -> Option<u64> {
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
