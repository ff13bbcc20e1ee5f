//! Timing figures of a recorded bench run: DCT_Sensors → TCU_ClutchCmd latency (recorder receive
//! timestamps), the same on a bare echo, and the cycle of both messages against the DBC's 10 ms.

use crate::can::messages::ids;
use crate::can::CanFrame;
use crate::daemon::tcu::CYCLE;
use crate::sim::buslog::{self, Spread};
use serde::Serialize;
use std::time::Duration;

/// Timing figures of a recorded run.
#[derive(Debug, Clone, Serialize)]
pub struct Timing {
    /// DCT_Sensors → TCU_ClutchCmd latency (µs).
    pub tcu_latency: Spread,
    pub tcu_latency_missed: usize,
    /// The bare echo on the same bus (µs), if measured.
    pub echo_latency: Option<Spread>,
    /// TCU_ClutchCmd intervals and |interval − 10 ms| (µs).
    pub clutch_cmd_interval: Spread,
    pub clutch_cmd_jitter: Spread,
    /// DCT_Sensors intervals and jitter (the plant's cycle, for comparison).
    pub sensors_interval: Spread,
    pub sensors_jitter: Spread,
}

/// The figures of a recording, beside its echo recording if one was made.
pub fn timing(frames: &[(Duration, CanFrame)], echo: Option<&[(Duration, CanFrame)]>) -> Timing {
    let (tcu_latency, tcu_latency_missed) =
        buslog::latency(frames, ids::DCT_SENSORS, ids::TCU_CLUTCH_CMD);
    let echo_latency = echo.map(|e| buslog::latency(e, ids::DCT_SENSORS, ids::TCU_CLUTCH_CMD).0);
    let (clutch_cmd_interval, clutch_cmd_jitter) =
        buslog::cycle_jitter(frames, ids::TCU_CLUTCH_CMD, CYCLE);
    let (sensors_interval, sensors_jitter) = buslog::cycle_jitter(frames, ids::DCT_SENSORS, CYCLE);
    Timing {
        tcu_latency,
        tcu_latency_missed,
        echo_latency,
        clutch_cmd_interval,
        clutch_cmd_jitter,
        sensors_interval,
        sensors_jitter,
    }
}
