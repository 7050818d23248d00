//! Placeholder of the seed 004 IMU fusion (replaced by the fusion module).
use protocol::pi_spi::ImuData;

/// IMU fusion.
#[derive(Clone, Debug)]
pub struct ImuFusion {
    _hz: u32,
}

/// Why an orientation was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OrientationError {
    /// Not a rotation.
    NotRotation = 1,
}

impl ImuFusion {
    /// New.
    pub fn new(sample_hz: u32) -> Self {
        Self { _hz: sample_hz }
    }
    /// Orientation.
    pub fn set_orientation(&mut self, _g: [i8; 9], _c: [i8; 9]) -> Result<(), OrientationError> {
        Ok(())
    }
    /// Update.
    pub fn update(&mut self, _a: [i16; 3], _g: [i16; 3], _t: i16) -> ImuData {
        ImuData::default()
    }
    /// Lost.
    pub fn sensor_lost(&mut self) -> ImuData {
        ImuData::default()
    }
}
