//! What a study's records say: the terminal tables of `collide results` (`tables`; the
//! configurations' table and its exports in `configurations`, times and digits in
//! `units`), the pure analyses (`analysis`: speedup, efficiency, Karp–Flatt, Amdahl; `accuracy`:
//! errors against the event reference, the Pareto front), the figures (`figures`, one
//! file per figure) and the markdown report (`markdown`). Reads records; runs nothing.

pub mod accuracy;
pub mod analysis;
pub mod configurations;
pub mod figures;
pub mod markdown;
pub mod prediction;
pub mod tables;
pub mod units;
