//! The bus a bench runs on: SocketCAN (vcan) or the in-process bus, behind one [`Bus`] type so
//! every node function serves both.

use crate::can::socketcan::SocketCanBus;
use crate::can::{
    Bus, BusError, CanFrame, EndpointConfig, InProcessBus, InProcessEndpoint, Received,
};
use std::future::Future;

/// Either bus's node.
pub enum AnyBus {
    Can(SocketCanBus),
    Sim(InProcessEndpoint),
}

#[allow(clippy::manual_async_fn)]
impl Bus for AnyBus {
    fn send(&mut self, frame: CanFrame) -> impl Future<Output = Result<(), BusError>> + Send {
        async move {
            match self {
                AnyBus::Can(b) => b.send(frame).await,
                AnyBus::Sim(b) => b.send(frame).await,
            }
        }
    }
    fn recv(&mut self) -> impl Future<Output = Result<Received, BusError>> + Send {
        async move {
            match self {
                AnyBus::Can(b) => b.recv().await,
                AnyBus::Sim(b) => b.recv().await,
            }
        }
    }
    fn try_recv(&mut self) -> Result<Option<Received>, BusError> {
        match self {
            AnyBus::Can(b) => b.try_recv(),
            AnyBus::Sim(b) => b.try_recv(),
        }
    }
    fn try_recv_many(&mut self, max: usize, out: &mut Vec<Result<Received, BusError>>) -> bool {
        match self {
            AnyBus::Can(b) => b.try_recv_many(max, out),
            AnyBus::Sim(b) => b.try_recv_many(max, out),
        }
    }
    fn iface(&self) -> &str {
        match self {
            AnyBus::Can(b) => b.iface(),
            AnyBus::Sim(b) => b.iface(),
        }
    }
}

/// The bus: a SocketCAN interface by name, or an in-process bus.
#[derive(Clone)]
pub enum Net {
    Can(String),
    Sim(InProcessBus),
}

impl Net {
    /// A new node; must be called on the runtime (thread) that will use it.
    pub fn open(&self) -> Result<AnyBus, BusError> {
        self.open_filtered(&[])
    }

    /// A new node receiving only `ids` (all frames when empty; the filter is the kernel's on
    /// SocketCAN, none on the in-process bus).
    pub fn open_filtered(&self, ids: &[u16]) -> Result<AnyBus, BusError> {
        Ok(match self {
            Net::Can(i) => {
                let b = SocketCanBus::open(i, false)?;
                if !ids.is_empty() {
                    b.set_filter_ids(ids)?;
                }
                AnyBus::Can(b)
            }
            Net::Sim(b) => AnyBus::Sim(b.endpoint(EndpointConfig::default())),
        })
    }

    /// The interface's name (`sim` for the in-process bus).
    pub fn name(&self) -> String {
        match self {
            Net::Can(i) => i.clone(),
            Net::Sim(_) => "sim".into(),
        }
    }
}
