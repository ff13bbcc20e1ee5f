//! The bench harness of `ddct bench`: the plant and TCU daemons and a recorder, each on its own
//! thread, runtime and node of one bus (vcan, or the in-process bus), in real time; and the bare
//! frame echo the TCU's latency is compared with (issue 12: moved here out of the CLI).
//!
//! Every hand-over is a readiness signal, never a sleep: a node starts talking only once the
//! nodes that must hear it say their sockets listen ([`recorder::Recorder::spawn`], the TCU's
//! ready channel), and a run ends once the recorder has seen every frame the plant (or the
//! pinger) sent and the TCU's answer to the last DCT_Sensors frame ([`recorder::Recorder::settle`],
//! bounded by a timeout for a TCU that no longer answers).
//!
//! [`timing`] turns the recording into the latency and cycle figures (pure); [`analyse`] turns a
//! recording (a run's, or a log recorded elsewhere) into the metrics, the lockstep simulation
//! beside it, the verdict and the HTML report (pure: the caller writes the files). [`tester`] is
//! a UDS tester on the bus (`ddct diag`).

pub mod analyse;
pub mod harness;
pub mod net;
pub mod recorder;
pub mod tester;
pub mod timing;

pub use harness::{bench_run, echo_run, BenchError, BenchPacing, RunResult, LOCKSTEP_TIMEOUT};
pub use net::{AnyBus, Net};
pub use recorder::{Recorder, Seen};
pub use timing::{timing, Timing};
