//! Raw register access: whole-register writes and read-modify-writes from named RM0090 bits.

/// Writes a whole 32-bit register.
pub(crate) fn wr<REG>(reg: &stm32f4::Reg<REG>, value: u32)
where
    REG: stm32f4::RegisterSpec<Ux = u32> + stm32f4::Writable + stm32f4::Resettable,
{
    // SAFETY: every caller passes a value assembled from the RM0090 bit definitions named beside
    // it; no reserved bit is set. The write has no memory-safety effect beyond the peripheral.
    reg.write(|w| unsafe { w.bits(value) });
}

/// Writes a whole 16-bit register.
pub(crate) fn wr16<REG>(reg: &stm32f4::Reg<REG>, value: u16)
where
    REG: stm32f4::RegisterSpec<Ux = u16> + stm32f4::Writable + stm32f4::Resettable,
{
    // SAFETY: as for `wr`: values come from the RM0090 bit definitions named at each call.
    reg.write(|w| unsafe { w.bits(value) });
}

/// Read-modify-write: clears `clear`, then sets `set`.
pub(crate) fn rmw<REG>(reg: &stm32f4::Reg<REG>, clear: u32, set: u32)
where
    REG: stm32f4::RegisterSpec<Ux = u32> + stm32f4::Writable + stm32f4::Readable,
{
    // SAFETY: as for `wr`: only documented bits of the register change.
    reg.modify(|r, w| unsafe { w.bits((r.bits() & !clear) | set) });
}

// RM0090 §17.4 (TIM1/TIM8) bit positions.
pub(crate) const CR1_CEN: u32 = 1 << 0;
pub(crate) const CR1_URS: u32 = 1 << 2;
pub(crate) const CR1_CMS_CENTER1: u32 = 0b01 << 5;
pub(crate) const CR1_ARPE: u32 = 1 << 7;
pub(crate) const CR2_MMS_ENABLE: u32 = 0b001 << 4;
pub(crate) const DIER_UIE: u32 = 1 << 0;
pub(crate) const SR_UIF: u32 = 1 << 0;
pub(crate) const SR_BIF: u32 = 1 << 7;
pub(crate) const EGR_UG: u32 = 1 << 0;
pub(crate) const OCM_PWM1: u32 = 0b110;
pub(crate) const OCM_FORCE_INACTIVE: u32 = 0b100;
pub(crate) const OCPE: u32 = 1 << 3;
pub(crate) const BDTR_LOCK1: u32 = 0b01 << 8;
pub(crate) const BDTR_OSSI: u32 = 1 << 10;
pub(crate) const BDTR_OSSR: u32 = 1 << 11;
pub(crate) const BDTR_BKE: u32 = 1 << 12;
pub(crate) const BDTR_MOE: u32 = 1 << 15;
pub(crate) const SMCR_TRIGGER_ITR0: u32 = 0b110; // SMS = trigger mode, TS = 000 (ITR0 = TIM1 for TIM8)

/// CCMR1 value putting channels 1 and 2 in output-compare mode `ocm` with preload.
pub(crate) const fn ccmr1(ocm: u32) -> u32 {
    (ocm << 4) | OCPE | (ocm << 12) | (OCPE << 8)
}

/// Read-modify-write of a 16-bit register: clears `clear`, then sets `set`.
pub(crate) fn rmw16<REG>(reg: &stm32f4::Reg<REG>, clear: u16, set: u16)
where
    REG: stm32f4::RegisterSpec<Ux = u16> + stm32f4::Writable + stm32f4::Readable,
{
    // SAFETY: as for `wr`: only documented bits of the register change.
    reg.modify(|r, w| unsafe { w.bits((r.bits() & !clear) | set) });
}
