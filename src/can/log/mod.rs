//! What `ddct log` does with a bus log, as a library the CLI is a thin shell over: [`decode()`]
//! a log with the contract or a DBC file into a table, CSV, JSON lines or Parquet ([`Format`]),
//! what the log itself said besides its frames counted in a [`Tally`]; [`convert`] frames
//! between candump text, MDF 4 and frame tables; [`stats`], the cycle-time table of a log.
//! The caller opens files, sockets and terminals and hands readers and writers in.

pub mod convert;
mod csv_threads;
mod decode;
mod error;
pub mod record;
mod shown;
mod sink;
pub mod stats;
mod tally;

pub use decode::{decode, message_ids, LogInput};
pub use error::{DecodeError, UnknownMessage};
pub use shown::AnyDecoder;
pub use sink::Format;
pub use tally::{Progress, Tally};
