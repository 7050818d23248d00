//! The seed 001 board (`cdc` image): four DC motors on two TB6612-style dual drivers, MPU6050,
//! battery voltage, and the `AA 55` link on USART1.
//!
//! # Pin map (STM32F407VGT6)
//!
//! | function                               | pin          | peripheral / AF          | notes                                   |
//! |----------------------------------------|--------------|--------------------------|-----------------------------------------|
//! | motor 1 … 4 PWM (TB1_A, TB1_B, TB2_A, TB2_B) | PC6 / PC7 / PC8 / PC9 | TIM8_CH1 … CH4, AF3 | 20 kHz edge-aligned, CCR = \|pwm\|·ARR/1000 |
//! | motor 1 IN1 / IN2                      | PE0 / PE1    | output                   | the seed's direction table              |
//! | motor 2 IN1 / IN2                      | PE2 / PE3    | output                   |                                         |
//! | motor 3 IN1 / IN2                      | PE4 / PE5    | output                   |                                         |
//! | motor 4 IN1 / IN2                      | PE6 / PE7    | output                   |                                         |
//! | driver standby (STBY, both drivers)    | PD0          | output                   | external pull-down: drivers off in reset |
//! | ESTOP loop                             | PD4          | input, pull-up, EXTI4    | as on every board: high = pressed or cut |
//! | MPU6050 SCL / SDA                      | PB6 / PB7    | I2C1, AF4, 400 kHz       | address 0x68 (AD0 low)                  |
//! | battery voltage (divider 100 k / 10 k) | PC4          | ADC1_IN14                | mV = raw · 3300 · 11 / 4095             |
//! | link TX / RX (UART variant)            | PA9 / PA10   | USART1, AF7, 115 200 8N1 | or USB OTG FS on PA11 / PA12            |
//! | SWD                                    | PA13 / PA14  |                          | probe-rs, defmt over RTT                |
//!
//! ```text
//!  TIM2  1 kHz  watchdog_tick   (ladder tick, motor outputs, STATUS every 100 ms)
//!  TIM3  100 Hz imu_read        (MPU6050 over I2C, battery ADC, IMU_MPU6050 frame)
//!  IWDG  20 ms nominal, fed by the tick
//! ```
//!
//! The drive stage is `mcu::cdc::motor_outputs`: this module only writes its CCR and IN1/IN2 values.
//! Start-up leaves every motor shorted (IN1 = IN2 = 1) with STBY low until the outputs are set.

use super::regs::*;
use super::{APB2_TIMER_HZ, SYSCLK_HZ};
use mcu::cdc::{MotorOutput, MOTORS};
use mcu::timing::timer_divider;
use stm32f4xx_hal::pac;
use stm32f4xx_hal::rcc::{Enable, Reset};

/// PWM frequency of the motor outputs, Hz.
pub const PWM_HZ: u32 = 20_000;
/// TIM8 auto-reload for [`PWM_HZ`] edge-aligned (no prescaler).
pub const PWM_ARR: u16 = match timer_divider(APB2_TIMER_HZ, PWM_HZ) {
    Some((0, arr)) if arr < u16::MAX => arr,
    _ => panic!("motor PWM rate is not an exact divisor of the timer clock"),
};
/// IMU and battery sampling rate, Hz (the seed: 100–200 Hz).
pub const IMU_HZ: u32 = 100;
/// TIM3 divider for [`IMU_HZ`].
pub const IMU_DIV: (u16, u16) = match timer_divider(super::APB1_TIMER_HZ, IMU_HZ) {
    Some(d) => d,
    None => panic!("IMU rate is not an exact divisor of the timer clock"),
};
/// A compare of this value keeps the output high the whole period (PWM mode 1: high while
/// CNT < CCR): the full scale of `mcu::cdc::motor_outputs`.
pub const PWM_FULL: u16 = PWM_ARR + 1;
const _: () = assert!(SYSCLK_HZ >= APB2_TIMER_HZ / 2);

const CCMR_PWM1_PRELOAD: u32 = (0b110 << 4) | (1 << 3);
const CCER_ALL: u32 = 1 | (1 << 4) | (1 << 8) | (1 << 12);
const BDTR_MOE: u32 = 1 << 15;
const CR1_ARPE: u32 = 1 << 7;

/// The four motor outputs: TIM8 compares and the IN1/IN2 lines on PE0 … PE7.
pub struct Motors {
    tim: pac::TIM8,
    gpioe: pac::GPIOE,
}

impl Motors {
    /// TIM8 in PWM mode 1 on CH1 … CH4 at [`PWM_HZ`], PE0 … PE7 as outputs, every motor shorted.
    pub fn new(tim: pac::TIM8, gpioe: pac::GPIOE, rcc: &mut pac::RCC) -> Self {
        pac::TIM8::enable(rcc);
        pac::TIM8::reset(rcc);
        pac::GPIOE::enable(rcc);
        let mut m = Self { tim, gpioe };
        m.set(&[MotorOutput::short(PWM_FULL); MOTORS]);
        // PE0 … PE7 general-purpose outputs (MODER 01 each), after their levels are set.
        rmw(m.gpioe.moder(), 0xFFFF, 0x5555);
        let t = &m.tim;
        wr(t.psc(), 0);
        wr(t.arr(), u32::from(PWM_ARR));
        wr(
            t.ccmr1_output(),
            CCMR_PWM1_PRELOAD | (CCMR_PWM1_PRELOAD << 8),
        );
        wr(
            t.ccmr2_output(),
            CCMR_PWM1_PRELOAD | (CCMR_PWM1_PRELOAD << 8),
        );
        wr(t.ccer(), CCER_ALL);
        wr(t.bdtr(), BDTR_MOE);
        wr(t.egr(), 1);
        wr(t.cr1(), CR1_ARPE | 1);
        m
    }

    /// Writes every motor's compare and direction lines (one BSRR write for all eight lines).
    pub fn set(&mut self, out: &[MotorOutput; MOTORS]) {
        let t = &self.tim;
        let [a, b, c, d] = out.map(|o| u32::from(o.ccr.min(PWM_FULL)));
        wr(t.ccr1(), a);
        wr(t.ccr2(), b);
        wr(t.ccr3(), c);
        wr(t.ccr4(), d);
        let mut set = 0u32;
        // IN1 of motor k on PE(2k), IN2 on PE(2k + 1).
        for (o, in1) in out.iter().zip([1u32 << 0, 1 << 2, 1 << 4, 1 << 6]) {
            let in2 = in1 << 1;
            set |= if o.in1 { in1 } else { in1 << 16 };
            set |= if o.in2 { in2 } else { in2 << 16 };
        }
        wr(self.gpioe.bsrr(), set);
    }

    /// Every motor shorted at once (ESTOP edge).
    pub fn brake(&mut self) {
        self.set(&[MotorOutput::short(PWM_FULL); MOTORS]);
    }
}

/// The output codes of the trace (`board::trace`): +CCR forward, −CCR reverse, `C` coast
/// (code 0 with both lines low), `S` short (both lines high).
pub fn trace_codes(out: &[MotorOutput; MOTORS]) -> [i32; 4] {
    out.map(|o| match (o.in1, o.in2) {
        (true, false) => i32::from(o.ccr),
        (false, true) => i32::from(o.ccr).wrapping_neg(),
        (false, false) => 0,
        (true, true) => SHORT_CODE,
    })
}

/// The trace code of a shorted motor.
const SHORT_CODE: i32 = i32::MIN;

/// Renders a trace code.
pub fn trace_token(code: i32) -> super::trace::Token {
    use super::trace::Token;
    match code {
        SHORT_CODE => Token::Letter('S'),
        0 => Token::Letter('C'),
        n => Token::Num(n),
    }
}

/// Battery voltage from ADC1 channel 14 (PC4), one software-started conversion.
pub struct Vbat {
    adc: pac::ADC1,
}

impl Vbat {
    /// ADC1 on, channel 14, 480-cycle sampling (the divider's 9 kΩ source impedance).
    pub fn new(adc: pac::ADC1, rcc: &mut pac::RCC) -> Self {
        pac::ADC1::enable(rcc);
        wr(adc.smpr1(), 0b111 << 12); // SMP14 = 480 cycles
        wr(adc.sqr3(), 14);
        wr(adc.cr2(), 1); // ADON
        Self { adc }
    }

    /// One conversion in mV, `None` if it did not finish in time (the conversion takes
    /// 495 ADC cycles, about 24 µs).
    pub fn read_mv(&mut self) -> Option<u16> {
        rmw(self.adc.cr2(), 0, 1 << 30); // SWSTART
        for _ in 0..10_000u32 {
            if self.adc.sr().read().bits() & (1 << 1) != 0 {
                let raw = self.adc.dr().read().bits() & 0xFFF;
                // raw ≤ 4095: the product stays below 2²⁸.
                return u16::try_from(raw.wrapping_mul(3300 * 11) / 4095).ok();
            }
        }
        None
    }
}

/// The MPU6050's registers as `mcu::cdc::imu_from_raw` takes them: accelerometer, temperature,
/// gyroscope.
pub type ImuRaw = ([i16; 3], i16, [i16; 3]);

/// The I2C bus of the MPU6050.
#[cfg(not(feature = "qemu"))]
pub type ImuBus = stm32f4xx_hal::i2c::I2c<pac::I2C1>;

/// The MPU6050 through the `mpu6050-dmp` driver. A sensor that does not answer (absent, or it
/// stopped) is retried every [`IMU_RETRY`] reads; until then `read` returns `None` and STATUS
/// reports `IMU_FAIL`.
#[cfg(not(feature = "qemu"))]
pub struct Imu {
    state: ImuState,
    retry_in: u32,
}

#[cfg(not(feature = "qemu"))]
enum ImuState {
    Up(mpu6050_dmp::sensor::Mpu6050<ImuBus>),
    Down(ImuBus),
    Lost,
}

/// Reads between two attempts to bring a silent MPU6050 back (1 s at [`IMU_HZ`]).
pub const IMU_RETRY: u32 = IMU_HZ;

#[cfg(not(feature = "qemu"))]
impl Imu {
    /// Wakes the sensor (its reset full scales: ±2 g, ±250 dps, as `mcu::cdc::IMU_SCALE` says).
    pub fn new(bus: ImuBus) -> Self {
        let mut s = Self {
            state: ImuState::Down(bus),
            retry_in: 0,
        };
        s.wake();
        s
    }

    fn wake(&mut self) {
        use mpu6050_dmp::{address::Address, sensor::Mpu6050};
        self.state = match core::mem::replace(&mut self.state, ImuState::Lost) {
            ImuState::Down(bus) => match Mpu6050::new(bus, Address::default()) {
                Ok(dev) => ImuState::Up(dev),
                Err(e) => ImuState::Down(e.i2c),
            },
            other => other,
        };
        self.retry_in = IMU_RETRY;
    }

    /// One reading, `None` if the sensor did not answer.
    pub fn read(&mut self) -> Option<ImuRaw> {
        match &mut self.state {
            ImuState::Up(dev) => {
                let r = dev
                    .motion6()
                    .and_then(|(a, g)| dev.temperature().map(|t| (a, g, t)));
                match r {
                    Ok((a, g, t)) => Some(([a.x(), a.y(), a.z()], t.raw(), [g.x(), g.y(), g.z()])),
                    Err(_) => {
                        if let ImuState::Up(dev) =
                            core::mem::replace(&mut self.state, ImuState::Lost)
                        {
                            self.state = ImuState::Down(dev.release());
                        }
                        self.retry_in = IMU_RETRY;
                        None
                    }
                }
            }
            ImuState::Down(_) => {
                self.retry_in = self.retry_in.saturating_sub(1);
                if self.retry_in == 0 {
                    self.wake();
                }
                None
            }
            ImuState::Lost => None,
        }
    }
}

/// Under the emulator there is no I2C model: the sensor is absent, and reported so.
#[cfg(feature = "qemu")]
pub struct Imu;

#[cfg(feature = "qemu")]
impl Imu {
    /// Never answers.
    pub fn read(&mut self) -> Option<ImuRaw> {
        None
    }
}

/// The link of this build: USART1, or USB CDC ACM with feature `usb`.
#[cfg(not(feature = "usb"))]
pub type Port = super::uart::Uart;
/// The link of this build: USB CDC ACM (feature `usb`).
#[cfg(feature = "usb")]
pub type Port = super::usb::UsbLink;

/// Static memory the link needs (USB's endpoint memory; nothing for the UART).
#[cfg(not(feature = "usb"))]
pub type PortMem = ();
/// Static memory the link needs: the USB bus allocator and its endpoint memory.
#[cfg(feature = "usb")]
pub type PortMem = super::usb::Mem;
/// [`PortMem`] before `init`.
#[cfg(not(feature = "usb"))]
pub const PORT_MEM_INIT: PortMem = ();
/// [`PortMem`] before `init`.
#[cfg(feature = "usb")]
pub const PORT_MEM_INIT: PortMem = super::usb::MEM_INIT;

/// Everything `init` hands to the tasks of the `cdc` image.
pub struct CdcBoard {
    /// The four motor outputs.
    pub motors: Motors,
    /// The local ESTOP input.
    pub estop: super::EstopPin,
    /// The link.
    pub port: Port,
    /// 1 kHz tick timer.
    pub tick: super::Periodic<pac::TIM2>,
    /// 100 Hz IMU timer.
    pub imu_timer: super::Periodic<pac::TIM3>,
    /// The MPU6050.
    pub imu: Imu,
    /// Battery voltage.
    pub vbat: Vbat,
}

/// Brings up the seed 001 board with every motor shorted: clocks, ESTOP input, motor outputs,
/// link, sensors; the drivers leave standby last.
pub fn init(
    dp: pac::Peripherals,
    port_mem: &'static mut PortMem,
) -> (CdcBoard, pac::IWDG, pac::DBGMCU) {
    use stm32f4xx_hal::prelude::*;
    let mut rcc = super::clocks(dp.RCC);
    let gpioa = dp.GPIOA.split(&mut rcc);
    let gpiob = dp.GPIOB.split(&mut rcc);
    let gpioc = dp.GPIOC.split(&mut rcc);
    let gpiod = dp.GPIOD.split(&mut rcc);
    let mut stby = gpiod.pd0.into_push_pull_output();
    stby.set_low();
    let mut syscfg = dp.SYSCFG.constrain(&mut rcc);
    let mut exti = dp.EXTI;
    let estop = super::EstopPin::new(gpiod.pd4, &mut syscfg, &mut exti);
    #[cfg(not(feature = "qemu"))]
    let imu = Imu::new(dp.I2C1.i2c((gpiob.pb6, gpiob.pb7), 400.kHz(), &mut rcc));
    #[cfg(feature = "qemu")]
    let imu = {
        let _ = (dp.I2C1, gpiob.pb6, gpiob.pb7);
        Imu
    };
    let rcc_regs: &mut pac::RCC = &mut rcc;
    let motors = Motors::new(dp.TIM8, dp.GPIOE, rcc_regs);
    #[cfg(not(feature = "usb"))]
    let port = super::uart::Uart::new(dp.USART1, rcc_regs);
    let vbat = Vbat::new(dp.ADC1, rcc_regs);
    let tick = super::Periodic::<pac::TIM2>::new(dp.TIM2, rcc_regs);
    let imu_timer = super::Periodic::<pac::TIM3>::new(dp.TIM3, rcc_regs);
    let _ = (
        gpioc.pc6.into_alternate::<3>(),
        gpioc.pc7.into_alternate::<3>(),
        gpioc.pc8.into_alternate::<3>(),
        gpioc.pc9.into_alternate::<3>(),
        gpioc.pc4.into_analog(),
    );
    #[cfg(not(feature = "usb"))]
    let _ = (
        gpioa.pa9.into_alternate::<7>(),
        gpioa.pa10.into_alternate::<7>(),
    );
    #[cfg(feature = "usb")]
    let port = {
        let usb = stm32f4xx_hal::otg_fs::USB::new(
            (dp.OTG_FS_GLOBAL, dp.OTG_FS_DEVICE, dp.OTG_FS_PWRCLK),
            (gpioa.pa11, gpioa.pa12),
            &rcc.clocks,
        );
        super::usb::UsbLink::new(usb, port_mem)
    };
    #[cfg(not(feature = "usb"))]
    let () = *port_mem;
    // Every motor is shorted by its IN lines: the drivers may leave standby.
    stby.set_high();
    (
        CdcBoard {
            motors,
            estop,
            port,
            tick,
            imu_timer,
            imu,
            vbat,
        },
        dp.IWDG,
        dp.DBGMCU,
    )
}
