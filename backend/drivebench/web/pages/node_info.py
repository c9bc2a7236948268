"""How the Info tab shows the identity objects (CiA 301 0x1000, 0x1018): in words and decimal, raw hex on hover."""

from __future__ import annotations

from typing import NamedTuple

from drivebench.i18n import N_, _

# CiA device profile numbers (0x1000 bits 0-15) a drive engineer meets on this bench.
DEVICE_PROFILES = {0: N_("no standard device profile"), 401: N_("CiA 401 generic I/O"),
                   402: N_("CiA 402 drives and motion control"), 406: N_("CiA 406 encoders")}


class IdentityShown(NamedTuple):
    label: str
    ref: str
    text: str
    raw_hex: str  # the value as it travels, one hover away


def identity_text(ref: str, raw: int | None, vendor: tuple[int | None, str] = (None, "")) -> str:
    """The words for one identity value; ``vendor`` is the profile's vendor id and name (named when it matches)."""
    if raw is None:
        return "–"
    if ref == "0x1000":  # CiA 301 7.5.2.1: bits 0-15 device profile number, 16-31 additional information
        profile = raw & 0xFFFF
        name = _(DEVICE_PROFILES[profile]) if profile in DEVICE_PROFILES else _("device profile {number}").format(
            number=profile)
        extra = raw >> 16
        return _("{profile}, additional information {extra}").format(profile=name, extra=extra) if extra else name
    if ref == "0x1018.1":  # vendor ids are printed in hex by CiA and the manuals; the name says more
        vendor_id, vendor_name = vendor
        return f"0x{raw:08X}{f' · {vendor_name}' if vendor_id == raw and vendor_name else ''}"
    if ref == "0x1018.2":
        return f"0x{raw:08X}"
    if ref == "0x1018.3":  # CiA 301 7.5.2.22: major revision in bits 16-31, minor revision in bits 0-15
        return f"{raw >> 16}.{raw & 0xFFFF} (major.minor)"
    return str(raw)


def shown(label: str, ref: str, raw: int | None, vendor: tuple[int | None, str] = (None, "")) -> IdentityShown:
    return IdentityShown(label, ref, identity_text(ref, raw, vendor), f"0x{raw:08X}" if raw is not None else "")
