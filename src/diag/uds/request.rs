//! One UDS request as the server's services read it: its SID, its bytes and its sub-function.

use super::nrc::Sid;

/// A request split into its SID, sub-function and suppress bit.
pub(super) struct Request<'a> {
    pub(super) sid: Sid,
    pub(super) bytes: &'a [u8],
    /// The sub-function without the suppress bit (0 for services without one).
    pub(super) sub: u8,
}
