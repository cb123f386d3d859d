pub mod profile;
pub mod effects;
