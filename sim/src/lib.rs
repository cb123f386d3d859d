pub mod friction;
pub mod profile;
