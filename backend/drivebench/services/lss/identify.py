"""What an LSS address tells about a device, from the profiles' identities alone (no table in code): the profile
whose vendor ID and product code match; else the vendor's name (the ``vendor_name`` of the profiles with that vendor
ID), the product code and revision as numbers, and which profiles have that vendor ID. A profile without a product
code cannot be matched: that is said, and no product code is ever assumed."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from drivebench.device.profiles.profile import Profile
from drivebench.i18n import _
from drivebench.protocol.canopen.lss import LssAddress


@dataclass(frozen=True)
class Candidate:
    id: str
    name: str
    product_code: int | None


@dataclass(frozen=True)
class Identified:
    device: str | None
    """The product name of the profile that matches vendor ID and product code."""
    profile: str | None
    vendor_name: str | None
    """From the profiles with this vendor ID; None when none has it."""
    candidates: list[Candidate]
    """Profiles of this vendor ID that do not match the product code (none when one matches)."""
    text: str
    """In words, for the page's Device column."""


def identify(profiles: Iterable[Profile], address: LssAddress) -> Identified:
    same_vendor = [profile for profile in profiles if profile.identity.vendor_id == address.vendor]
    match = next((profile for profile in same_vendor if profile.identity.product_code == address.product), None)
    if match is not None:
        return Identified(match.identity.product_name, match.id, match.identity.vendor_name, [],
                          match.identity.product_name)
    numbers = _("product code {product} ({product_dec}), revision {revision} ({revision_dec})").format(
        product=f"0x{address.product:08X}", product_dec=address.product, revision=f"0x{address.revision:08X}",
        revision_dec=address.revision)
    if not same_vendor:
        text = _("No profile has vendor ID {vendor}: {numbers}. Upload the device's EDS to match it.").format(
            vendor=f"0x{address.vendor:08X}", numbers=numbers)
        return Identified(None, None, None, [], text)
    vendor_name = same_vendor[0].identity.vendor_name
    candidates = [Candidate(profile.id, profile.identity.product_name, profile.identity.product_code)
                  for profile in same_vendor]
    names = "; ".join(candidate.name for candidate in candidates)
    without = [candidate for candidate in candidates if candidate.product_code is None]
    text = _("{vendor} (vendor ID {vendor_id}), {numbers}: no profile has this product code. Profiles of this "
             "vendor: {names}.").format(vendor=vendor_name, vendor_id=f"0x{address.vendor:08X}", numbers=numbers,
                                        names=names)
    if without:
        text += " " + _("{count} of them carry no product code (their manual gives none), so the device cannot be "
                        "matched to one: pick the profile by the device's name plate.").format(count=len(without))
    return Identified(None, None, vendor_name, candidates, text)
