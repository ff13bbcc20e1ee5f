//! Why a decode run stopped ([`DecodeError`]).

use crate::can::columnar::ColumnarError;
use thiserror::Error;

/// Why a decode run stopped before the end of its input.
#[derive(Debug, Error)]
pub enum DecodeError {
    /// The input cannot be read further (not a malformed line: those are counted and skipped).
    #[error("{name}")]
    Input {
        name: String,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// Writing the output.
    #[error(transparent)]
    Write(#[from] std::io::Error),
    /// Writing the Parquet table.
    #[error(transparent)]
    Parquet(#[from] ColumnarError),
}

impl DecodeError {
    /// Whether the reader of the output went away (`ddct log decode … | head`).
    pub fn is_broken_pipe(&self) -> bool {
        matches!(self, DecodeError::Write(e) if e.kind() == std::io::ErrorKind::BrokenPipe)
    }
}

/// A `-m/--message` name or id that is not a message of the contract or DBC file decoded with.
#[derive(Debug, Error)]
#[error("{name}: not a message name or id of {of}")]
pub struct UnknownMessage {
    pub name: String,
    /// `the contract`, or the DBC file's path.
    pub of: String,
}
