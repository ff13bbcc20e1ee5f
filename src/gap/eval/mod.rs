//! The model replayed on measured data: a candidate's predictions channel by channel ([`predict`]), the thermal replay ([`replay`], the paper's (16)), the clutch-disk temperature estimate ([`disk`], (16c/d)), the thermal replay from per-record windows ([`fast_replay`]) and the effect hooks of a class set ([`set_hooks`]).

pub mod disk;
pub mod fast_replay;
pub mod predict;
pub mod replay;
pub mod set_hooks;
