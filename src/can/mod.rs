//! The bus layer: the DBC contract (generated message types), E2E protection, the `Bus` trait
//! with its SocketCAN and in-process implementations, and candump log I/O.

pub mod codec;
pub mod dbc;
pub mod messages;
