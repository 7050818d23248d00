//! Placeholder of the seed 004 odometry (replaced by the odometry module).
use protocol::pi_spi::{assumed::KinematicsConfig, OdometryData};

/// Odometry.
#[derive(Clone, Debug, Default)]
pub struct Odometry {
    d: OdometryData,
}

/// Why a kinematics block was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KinematicsError {
    /// Not finite.
    NonFinite = 1,
}

impl Odometry {
    /// New.
    pub const fn new() -> Self {
        Self {
            d: OdometryData {
                pos_x: 0.0,
                pos_y: 0.0,
                heading: 0.0,
                vx: 0.0,
                vy: 0.0,
                wz: 0.0,
            },
        }
    }
    /// Configure.
    pub fn configure(&mut self, _k: &KinematicsConfig) -> Result<(), KinematicsError> {
        Ok(())
    }
    /// Reset.
    pub fn reset(&mut self) {}
    /// Update.
    pub fn update(&mut self, _c: [i32; 4], _dt: f32) -> OdometryData {
        self.d
    }
}
