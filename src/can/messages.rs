//! The contract's message types, generated at build time from `dbc/ddct.dbc` (see `build.rs`):
//! one struct per message with `decode`, `encode` and range-checked setters, one enum per value
//! table, the `ids` constants and the `MESSAGES` table.

#![allow(clippy::all)]
include!(concat!(env!("OUT_DIR"), "/messages.rs"));

/// The definition of a message of the contract by id.
pub fn message_def(id: u32) -> Option<&'static MessageDef> {
    MESSAGES.iter().find(|m| u32::from(m.id) == id)
}

/// The definition of a message of the contract by name.
pub fn message_by_name(name: &str) -> Option<&'static MessageDef> {
    MESSAGES.iter().find(|m| m.name == name)
}
