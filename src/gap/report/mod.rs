//! Rendering a diagnosis: Markdown, JSON and figures ([`render`]), the findings as table rows ([`findings_table`]).

pub mod findings_table;
pub mod render;
