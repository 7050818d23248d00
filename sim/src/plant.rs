//! The plant: two brushed DC gearmotors with their H-bridges, wheels, and a differential-drive robot.
//!
//! Per motor (motor side, ω_m = N · ω_wheel):
//! ```text
//!   L di/dt = u − R i − Ke ω_m          u = duty · V_bus while driving, 0 while braking (shorted)
//!   τ_wheel = N · Kt · i
//! ```
//! Robot (no wheel slip), generalised speeds v (m/s) and ω (rad/s):
//! ```text
//!   M_eff dv/dt = (F_L + F_R) − c_v v − F_roll sign(v)     F = τ_wheel / r
//!   J_eff dω/dt = (F_R − F_L) b/2 − c_ω ω
//! ```
//! with the rotor inertia reflected into M_eff and J_eff. The electrical equation is integrated
//! exactly over one step for constant u and ω (zero-order hold), so the 0.5 ms electrical time
//! constant is resolved at any step; the mechanics use semi-implicit Euler (τ_mech ≫ step).
//!
//! The rolling constraint between the body velocity and the wheel speeds (ω_L, ω_R = (v ∓ ω b/2)/r
//! and back) is `control::DiffDrive`, the one copy of those formulas, not a second one here. Its
//! Q16.16 format costs the plant: the geometry is held to the nearest 2⁻¹⁶ m (15 µm; the dynamics
//! use the same held values, so the robot stays one rigid body), and the wheel speeds are computed
//! from v and ω rounded to 2⁻¹⁶ (1.5e-5 m/s, rad/s): on the default robot within about 1.3e-4
//! rad/s of the f64 formula with the same geometry (at 1 m/s and 1 rad/s), a back-EMF error of
//! 1e-4 V at 24 V and under a tenth of an encoder count per second of wheel angle. The state
//! (v, ω, pose, currents) and its integration stay f64.

use control::kinematics::{DiffDrive, KinematicsError, Twist};
use control::Q;
use serde::{Deserialize, Serialize};

/// Physical parameters. Defaults: a 24 V, 40 kg base with 20:1 gearmotors.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlantParams {
    /// Bus voltage, V.
    pub v_bus: f64,
    /// Winding resistance, Ω.
    pub r_ohm: f64,
    /// Winding inductance, H (L/R = 0.5 ms, seed 000's electrical time constant).
    pub l_h: f64,
    /// Torque constant = back-EMF constant, N·m/A = V·s/rad (motor side).
    pub kt: f64,
    /// Gear ratio (motor turns per wheel turn).
    pub gear: f64,
    /// Rotor inertia, kg·m² (motor side).
    pub j_rotor: f64,
    /// Robot mass, kg.
    pub mass_kg: f64,
    /// Robot yaw inertia, kg·m².
    pub yaw_inertia: f64,
    /// Wheel radius, m.
    pub wheel_radius_m: f64,
    /// Distance between the wheels, m.
    pub wheelbase_m: f64,
    /// Viscous drag on v, N·s/m.
    pub drag_v: f64,
    /// Viscous drag on ω, N·m·s.
    pub drag_w: f64,
    /// Rolling resistance force, N (acts against v).
    pub rolling_n: f64,
    /// Encoder counts per wheel revolution.
    pub counts_per_rev: u32,
}

impl Default for PlantParams {
    fn default() -> Self {
        Self {
            v_bus: 24.0,
            r_ohm: 1.0,
            l_h: 0.5e-3,
            kt: 0.04,
            gear: 20.0,
            j_rotor: 2.0e-5,
            mass_kg: 40.0,
            yaw_inertia: 1.5,
            wheel_radius_m: 0.08,
            wheelbase_m: 0.40,
            drag_v: 2.0,
            drag_w: 0.2,
            rolling_n: 4.0,
            counts_per_rev: 4096,
        }
    }
}

impl PlantParams {
    /// The geometry as `control::DiffDrive` holds it (the nearest 2⁻¹⁶ m), or why it is refused:
    /// the wheel radius must be 1 mm ..= 10 m and the wheelbase 1 cm ..= 64 m.
    pub fn kinematics(&self) -> Result<DiffDrive, KinematicsError> {
        let radius =
            Q::checked_from_num(self.wheel_radius_m).ok_or(KinematicsError::WheelRadius)?;
        let base = Q::checked_from_num(self.wheelbase_m).ok_or(KinematicsError::Wheelbase)?;
        DiffDrive::new(base, radius)
    }

    /// Electrical time constant L/R, s.
    pub fn tau_e(&self) -> f64 {
        self.l_h / self.r_ohm
    }

    /// Effective translational mass including both rotors, kg.
    pub fn m_eff(&self) -> f64 {
        self.m_eff_with(2.0)
    }

    /// Effective yaw inertia including both rotors, kg·m².
    pub fn j_eff(&self) -> f64 {
        self.j_eff_with(2.0)
    }

    /// Effective translational mass with `rotors` motors (half on each side), kg.
    pub fn m_eff_with(&self, rotors: f64) -> f64 {
        let r = self.wheel_radius_m;
        self.mass_kg + rotors * self.j_rotor * self.gear * self.gear / (r * r)
    }

    /// Effective yaw inertia with `rotors` motors (half on each side, at ± wheelbase/2), kg·m².
    pub fn j_eff_with(&self, rotors: f64) -> f64 {
        let r = self.wheel_radius_m;
        let h = self.wheelbase_m / 2.0;
        self.yaw_inertia + rotors * self.j_rotor * self.gear * self.gear * h * h / (r * r)
    }

    /// The winding current after one step of `L di/dt = u − R i − Ke ω_m`, integrated exactly for
    /// constant `u` (V) and wheel speed `wheel` (rad/s) from `i0` (A); `decay` is e^(−dt R / L).
    pub fn winding_current(&self, i0: f64, u: f64, wheel: f64, decay: f64) -> f64 {
        let emf = self.kt * self.gear * wheel;
        let i_inf = (u - emf) / self.r_ohm;
        i_inf + (i0 - i_inf) * decay
    }

    /// The force one motor's current `i` (A) puts on the ground at its wheel, N.
    pub fn wheel_force(&self, i: f64) -> f64 {
        self.gear * self.kt * i / self.wheel_radius_m
    }

    /// Braking force per m/s of both shorted motors in steady state (L neglected), N·s/m:
    /// each wheel gives N² Kt Ke / (R r²).
    pub fn short_brake_damping(&self) -> f64 {
        let r = self.wheel_radius_m;
        2.0 * self.gear * self.gear * self.kt * self.kt / (self.r_ohm * r * r)
    }
}

/// How the H-bridge of one motor is switched.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BridgeDrive {
    /// PWM with this average duty in [-1, 1].
    Pwm(f64),
    /// Low sides on: motor shorted (dynamic brake).
    Short,
}

/// The state of the plant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plant {
    /// Parameters (the geometry as held by `kinematics`).
    pub p: PlantParams,
    /// The rolling constraint between body velocity and wheel speeds.
    kinematics: DiffDrive,
    /// Motor currents (left, right), A.
    pub current: [f64; 2],
    /// Robot forward speed, m/s.
    pub v: f64,
    /// Robot yaw rate, rad/s.
    pub w: f64,
    /// Pose x, m.
    pub x: f64,
    /// Pose y, m.
    pub y: f64,
    /// Heading, rad.
    pub theta: f64,
    /// Distance travelled (path length), m.
    pub odometer: f64,
    /// Wheel angles (left, right), rad.
    pub wheel_angle: [f64; 2],
}

impl Plant {
    /// A plant at rest, or why its geometry is refused (see [`PlantParams::kinematics`]). The
    /// wheel radius and wheelbase in `p` are replaced by the values the kinematics hold.
    pub fn try_new(mut p: PlantParams) -> Result<Self, KinematicsError> {
        let kinematics = p.kinematics()?;
        p.wheel_radius_m = kinematics.wheel_radius().to_num();
        p.wheelbase_m = kinematics.wheelbase().to_num();
        Ok(Self {
            p,
            kinematics,
            current: [0.0; 2],
            v: 0.0,
            w: 0.0,
            x: 0.0,
            y: 0.0,
            theta: 0.0,
            odometer: 0.0,
            wheel_angle: [0.0; 2],
        })
    }

    /// A plant at rest.
    ///
    /// # Panics
    /// If the geometry is out of range; a scenario's parameters are checked when it is loaded
    /// (`Scenario::from_toml`), so only parameters built in code can get here unchecked.
    #[allow(
        clippy::panic,
        reason = "simulator set-up with unchecked parameters: a caller bug"
    )]
    pub fn new(p: PlantParams) -> Self {
        match Self::try_new(p) {
            Ok(plant) => plant,
            Err(e) => panic!("plant geometry out of range: {e:?}"),
        }
    }

    /// Wheel speeds (left, right), rad/s, from the body velocity.
    pub fn wheel_speeds(&self) -> [f64; 2] {
        let [l, r] = self.kinematics.inverse_unrounded(Twist {
            v: control::q_from_f64(self.v),
            omega: control::q_from_f64(self.w),
        });
        [l.to_num(), r.to_num()]
    }

    /// Sets the body velocity from wheel speeds (used to start a scenario in motion).
    pub fn set_wheel_speeds(&mut self, wl: f64, wr: f64) {
        let t = self
            .kinematics
            .forward(control::q_from_f64(wl), control::q_from_f64(wr));
        self.v = t.v.to_num();
        self.w = t.omega.to_num();
    }

    /// Advances by `dt` seconds with the bridges switched as given and `extra_v` volts of fault
    /// voltage across each motor (zero in normal operation).
    pub fn step(&mut self, dt: f64, drive: [BridgeDrive; 2], extra_v: [f64; 2]) {
        let p = self.p;
        let ws = self.wheel_speeds();
        let a = (-dt * p.r_ohm / p.l_h).exp();
        let mut force = [0.0; 2];
        for k in 0..2 {
            let (wk, ek, dk) = (ws[k], extra_v[k], drive[k]);
            let u = match dk {
                BridgeDrive::Pwm(d) => d.clamp(-1.0, 1.0) * p.v_bus,
                BridgeDrive::Short => 0.0,
            } + ek;
            let i = p.winding_current(self.current[k], u, wk, a);
            self.current[k] = i;
            force[k] = p.wheel_force(i);
        }
        self.move_body(dt, force, p.m_eff(), p.j_eff());
    }

    /// Advances the body by `dt` seconds under the total wheel force on each side (left, right),
    /// N, with the effective mass and yaw inertia given (they depend on the number of rotors).
    pub fn move_body(&mut self, dt: f64, force: [f64; 2], m_eff: f64, j_eff: f64) {
        let p = self.p;
        let h = p.wheelbase_m / 2.0;
        let roll = if self.v.abs() < 1e-4 {
            // Static: rolling resistance only opposes what would move the robot.
            let drive_f = force[0] + force[1];
            -drive_f.clamp(-p.rolling_n, p.rolling_n)
        } else {
            -p.rolling_n * self.v.signum()
        };
        let dv = (force[0] + force[1] - p.drag_v * self.v + roll) / m_eff;
        let dw = ((force[1] - force[0]) * h - p.drag_w * self.w) / j_eff;
        let v_new = self.v + dv * dt;
        // Rolling resistance cannot reverse the motion within a step.
        self.v = if self.v != 0.0
            && v_new.signum() != self.v.signum()
            && (force[0] + force[1]).abs() < p.rolling_n
        {
            0.0
        } else {
            v_new
        };
        self.w += dw * dt;
        self.theta += self.w * dt;
        self.x += self.v * self.theta.cos() * dt;
        self.y += self.v * self.theta.sin() * dt;
        self.odometer += self.v.abs() * dt;
        let ws2 = self.wheel_speeds();
        for k in 0..2 {
            self.wheel_angle[k] += ws2[k] * dt;
        }
    }

    /// The 16-bit encoder counter reading of wheel `k`.
    pub fn encoder_counter(&self, k: usize) -> u16 {
        let a = self.wheel_angle.get(k).copied().unwrap_or(0.0);
        let counts = (a * f64::from(self.p.counts_per_rev) / core::f64::consts::TAU).floor();
        (counts as i64) as u16
    }
}

impl Default for Plant {
    fn default() -> Self {
        Self::new(PlantParams::default())
    }
}

#[cfg(test)]
#[allow(clippy::indexing_slicing, clippy::arithmetic_side_effects)]
mod tests {
    use super::*;

    /// The rolling constraint on the default robot (L = 0.40 m, r = 0.08 m) by hand:
    /// ω_L,R = (v ∓ ω·0.2)/0.08 and back. The geometry is held as r = 0.0800018 m and
    /// L = 0.3999939 m (relative 2.3e-5 and 1.5e-5): at 8.75 rad/s that scale error alone is
    /// 8.75·2.3e-5 + 2.5·1.5e-5 = 2.4e-4 rad/s, hence 3e-4; the body velocity, 3e-5.
    #[test]
    fn rolling_constraint_by_hand() {
        let mut pl = Plant::new(PlantParams::default());
        pl.v = 0.5;
        pl.w = 1.0;
        let [l, r] = pl.wheel_speeds();
        assert!(
            (l - 3.75).abs() < 3e-4 && (r - 8.75).abs() < 3e-4,
            "{l} {r}"
        );
        pl.v = -0.4;
        pl.w = 0.5;
        let [l, r] = pl.wheel_speeds();
        assert!(
            (l + 6.25).abs() < 3e-4 && (r + 3.75).abs() < 3e-4,
            "{l} {r}"
        );
        // v = 0.08·(4 + 6)/2 = 0.4 m/s, ω = 0.08·(6 − 4)/0.4 = 0.4 rad/s.
        pl.set_wheel_speeds(4.0, 6.0);
        assert!(
            (pl.v - 0.4).abs() < 3e-5 && (pl.w - 0.4).abs() < 3e-5,
            "{} {}",
            pl.v,
            pl.w
        );
        // The dynamics use the geometry the kinematics hold.
        assert_eq!(pl.p.wheel_radius_m, 5243.0 / 65536.0);
        assert_eq!(pl.p.wheelbase_m, 26214.0 / 65536.0);
    }

    #[test]
    fn out_of_range_geometry_is_refused() {
        let p = PlantParams::default();
        for (radius, base, e) in [
            (0.0, 0.4, KinematicsError::WheelRadius),
            (f64::NAN, 0.4, KinematicsError::WheelRadius),
            (0.08, 100.0, KinematicsError::Wheelbase),
            (0.08, f64::INFINITY, KinematicsError::Wheelbase),
        ] {
            let bad = PlantParams {
                wheel_radius_m: radius,
                wheelbase_m: base,
                ..p
            };
            assert_eq!(Plant::try_new(bad), Err(e));
        }
    }

    #[test]
    fn electrical_time_constant_is_half_a_millisecond() {
        // Locked robot (huge mass): a 24 V step gives i(t) = 24 (1 − e^{−t/τ}) with τ = 0.5 ms.
        let p = PlantParams {
            mass_kg: 1e9,
            yaw_inertia: 1e9,
            ..PlantParams::default()
        };
        let mut pl = Plant::new(p);
        for _ in 0..10 {
            pl.step(50e-6, [BridgeDrive::Pwm(1.0); 2], [0.0; 2]);
        }
        // After 0.5 ms: 24 × (1 − 1/e) = 15.171 A.
        assert!((pl.current[0] - 15.171).abs() < 0.01, "{}", pl.current[0]);
    }

    #[test]
    fn steady_speed_matches_back_emf() {
        // Full duty, no load besides drag and rolling resistance: the motor settles a bit below
        // u / (Kt·N) = 24 / 0.8 = 30 rad/s at the wheel.
        let mut pl = Plant::new(PlantParams::default());
        for _ in 0..200_000 {
            pl.step(50e-6, [BridgeDrive::Pwm(1.0); 2], [0.0; 2]);
        }
        let w = pl.wheel_speeds()[0];
        assert!(w > 28.0 && w < 30.0, "{w}");
        assert!(pl.w.abs() < 1e-9);
    }

    #[test]
    fn shorted_motors_brake_with_the_predicted_time_constant() {
        let mut pl = Plant::new(PlantParams {
            rolling_n: 0.0,
            drag_v: 0.0,
            ..PlantParams::default()
        });
        pl.set_wheel_speeds(20.0, 20.0);
        let v0 = pl.v;
        let tau = pl.p.m_eff() / pl.p.short_brake_damping();
        let mut t = 0.0;
        while t < tau {
            pl.step(50e-6, [BridgeDrive::Short; 2], [0.0; 2]);
            t += 50e-6;
        }
        // Exponential decay: v(τ) = v0/e (the inductance delays the current by ~0.5 ms ≪ τ).
        let ratio = pl.v / v0;
        assert!((ratio - (-1.0f64).exp()).abs() < 0.01, "{ratio} tau {tau}");
        // Distance so far: v0 τ (1 − 1/e).
        let d = v0 * tau * (1.0 - (-1.0f64).exp());
        assert!((pl.odometer - d).abs() / d < 0.02, "{} vs {d}", pl.odometer);
    }
}
