//! Bench records as read (what the bench, the logger and the truth generator produce and the
//! diagnosis reads): the record schema, the CSV reader, the candump and MF4 decoding, resampling and cutting ([`dataset`]), the event segmentation of its series ([`events`]: engagements, locked and open phases, cooling), and the columns ↔ DBC signals table both ways ([`record_frames`]).

pub mod dataset;
pub mod events;
pub mod record_frames;
