//! `pop`: principal-ordinates propagation (paper 01). Being written (issue 3/9).

use super::{Progress, SolveOutput, Solver};
use crate::error::{Error, Result};
use crate::scene::Scene;

pub struct Pop;

impl Pop {
    pub fn from_settings(_map: &serde_json::Map<String, serde_json::Value>) -> Result<Self> {
        Ok(Pop)
    }
}

impl Solver for Pop {
    fn name(&self) -> &'static str {
        "pop"
    }
    fn solve(&self, _scene: &Scene, _progress: &dyn Progress) -> Result<SolveOutput> {
        Err(Error::InvalidArgument("solver `pop` is not implemented yet".into()))
    }
}
