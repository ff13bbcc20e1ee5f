//! The bus layer: the DBC contract (generated message types), E2E protection, the `Bus` trait
//! with its SocketCAN and in-process implementations, and candump log I/O; `runtime_dbc` decodes
//! logs with a DBC file given at run time instead of the contract; `columnar` writes decoded
//! signals as Parquet, `decode_csv` as CSV; `mf4` reads and writes MDF 4 bus-logging files;
//! `log` is what `ddct log` does with a log (decode runs into each format, conversion, cycle
//! statistics, recording), `replay` its sending at the log's timing.

pub mod bus;
pub mod candump;
mod candump_line;
pub mod candump_screen;
pub mod codec;
pub mod columnar;
pub mod columnar_frames;
pub mod dbc;
pub mod decode;
pub mod decode_csv;
pub mod e2e;
pub mod frame;
pub mod gear;
pub mod lines;
pub mod log;
pub mod logfile;
pub mod messages;
pub mod mf4;
pub mod monitor;
pub mod replay;
pub mod runtime_dbc;
pub mod socketcan;

pub use bus::{
    Bus, BusError, Clock, EndpointConfig, InProcessBus, InProcessEndpoint, ManualClock, Received,
    SystemClock,
};
pub use frame::CanFrame;
