"""The devices of the network planner and the COB-ID table: every loaded CANopen profile, not only those with DIP
switches.

A profile with a ``switches`` section is planned by that section (``device/calculators/switches.py``, as the calculator
uses it). Any other CANopen profile (a shipped one without switches, an uploaded EDS or XDD) is planned from its own
data and the standard:

* node ids: ``features.node_id_range`` (an EDS: CiA 301's 1 … 127);
* bit rates: ``features.baud_rates_kbit`` (an EDS: its ``[DeviceInfo] BaudRate_xxx = 1``);
* COB-IDs: the default values of its communication objects (SDO server 0x1200, RPDO 0x1400…, TPDO 0x1800…, EMCY
  0x1014, SYNC 0x1005: a ``$NODEID`` formula is node specific, bit 31 set = off in the factory setting; each PDO is
  a channel of its own, ``tpdo1``, ``rpdo1`` …, as its COB-ID object switches it), where the
  profile has none CiA 301's predefined connection set (PDO 1 … 4 for the PDO counts ``features`` gives), its
  additional SDO servers from the ``sdo_channels`` section, NMT and heartbeat by CiA 301.

An EtherCAT slave (``features.transport``) has no node id, bit rate or COB-IDs to plan: looking it up raises
:class:`NotOnCanBus`, which says so.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from drivebench.device.calculators.dip import SwitchDevice, SwitchDevices
from drivebench.device.calculators.switches import CobIdRules, Direction, Service, SwitchesSection
from drivebench.device.formats.eds_quirks import node_expr
from drivebench.device.profiles.profile import ObjectEntry, Profile
from drivebench.errors import InvalidValue, UnknownProfile
from drivebench.i18n import N_, _

PREDEFINED_PDOS = 4
"""CiA 301's predefined connection set gives COB-IDs to PDO 1 … 4 only."""
CIA301 = "CiA 301"
VALID_ID_MASK = 0x7FF
NOT_VALID = 1 << 31


class NotOnCanBus(InvalidValue):
    """The device is on another fieldbus: a CAN plan (node id, bit rate, COB-IDs) does not apply to it."""

    title = N_("Not a CANopen device")


@dataclass(frozen=True)
class BusRules:
    """What the planner needs of a device without a ``switches`` section (the same names as that section)."""

    key: str
    name: str
    short_name: str
    node_range: tuple[int, int]
    baud_rates_kbit: list[int]
    cob_ids: CobIdRules


@dataclass(frozen=True)
class BusDevice:
    spec: SwitchesSection | BusRules
    profile_ids: tuple[str, ...]
    vendor_id: int | None

    @property
    def has_switches(self) -> bool:
        return isinstance(self.spec, SwitchesSection)


def _is_ethercat(profile: Profile) -> bool:
    return profile.features.transport != "canopen"


def _default(objects: dict[tuple[int, int], ObjectEntry], index: int, sub: int) -> tuple[int, bool] | None:
    """(COB-ID value, node specific) of an object's default, None when the profile gives none."""
    entry = objects.get((index, sub))
    if entry is None:
        return None
    if entry.default_expr:
        constant = node_expr(entry.default_expr)
        if constant is not None:
            return constant, True
    if isinstance(entry.default, int):
        return entry.default, False
    return None


def _service(name: str, channel: str, direction: Direction, found: tuple[int, bool] | None, standard: int,
             where: str) -> Service:
    """A service from an object's default (``where``), else from the standard base."""
    if found is None:
        return Service(name=name, channel=channel, base=standard, direction=direction,
                       source=_("{standard} predefined connection set").format(standard=CIA301))
    value, node_specific = found
    return Service(name=name, channel=channel, base=value & VALID_ID_MASK, direction=direction,
                   node_specific=node_specific, default_on=not value & NOT_VALID,
                   source=_("default of {object}").format(object=where))


def _pdo_services(profile: Profile, objects: dict[tuple[int, int], ObjectEntry]) -> list[Service]:
    services = []
    counts = {"TPDO": profile.features.tpdo_count, "RPDO": profile.features.rpdo_count}
    comm = {"TPDO": 0x1800, "RPDO": 0x1400}
    standard = {"TPDO": 0x180, "RPDO": 0x200}
    direction: dict[str, Direction] = {"TPDO": "from node", "RPDO": "to node"}
    listed = {kind: sorted(i - comm[kind] + 1 for i, s in objects if s == 1 and comm[kind] <= i < comm[kind] + 0x200)
              for kind in comm}
    for kind in ("TPDO", "RPDO"):
        numbers = listed[kind] or list(range(1, min(counts[kind], PREDEFINED_PDOS) + 1))
        for number in numbers:
            found = _default(objects, comm[kind] + number - 1, 1)
            if found is None and number > PREDEFINED_PDOS:
                continue  # no default COB-ID in the profile and none in CiA 301
            services.append(_service(f"{kind}{number}", f"{kind.lower()}{number}", direction[kind], found,
                                     standard[kind] + 0x100 * (number - 1), f"0x{comm[kind] + number - 1:04X}sub1"))
    return sorted(services, key=lambda s: (int(s.channel[4:]), s.direction != "from node"))


def derived_cob_ids(profile: Profile) -> CobIdRules:
    """The COB-ID rules of a profile without a ``switches`` section, from its objects and CiA 301."""
    objects = {(o.index, o.subindex): o for o in profile.objects}
    sync = _default(objects, 0x1005, 0)
    services = [
        Service(name="NMT", channel="nmt", base=0, direction="to node", node_specific=False, source=CIA301),
        Service(name="SYNC", channel="sync", base=(sync[0] if sync else 0x80) & VALID_ID_MASK, direction="broadcast",
                node_specific=False, source=_("default of {object}").format(object="0x1005") if sync else CIA301),
        _service("EMCY", "emcy", "from node", _default(objects, 0x1014, 0), 0x80, "0x1014"),
        *_pdo_services(profile, objects),
        _service("SDO1 tx", "sdo1", "from node", _default(objects, 0x1200, 2), 0x580, "0x1200sub2"),
        _service("SDO1 rx", "sdo1", "to node", _default(objects, 0x1200, 1), 0x600, "0x1200sub1"),
    ]
    for channel in profile.sdo_channels:
        ways: tuple[tuple[Direction, int, str], ...] = (("from node", channel.tx_base, "SDO1 tx"),
                                                         ("to node", channel.rx_base, "SDO1 rx"))
        for direction, base, first in ways:
            first_base = next(s.base for s in services if s.name == first)
            shares = first if 0 < base - first_base < 128 else None
            services.append(Service(name=f"SDO{channel.number} {first.split()[1]}", channel=f"sdo{channel.number}",
                                    base=base, direction=direction, default_on=False, shares_with=shares,
                                    source=channel.source or ""))
    services.append(Service(name="Heartbeat / boot-up", channel="heartbeat", base=0x700, direction="from node",
                            source=CIA301))
    rates = ", ".join(map(str, profile.features.baud_rates_kbit)) or _("none")
    lo, hi = profile.features.node_id_range
    notes = [_("No DIP switches in this profile: node ids {lo} … {hi} and the bit rates {rates} kbit/s come from the "
               "profile (an EDS: [DeviceInfo] BaudRate_xxx), the COB-IDs from its objects' default values or CiA "
               "301's predefined connection set.").format(lo=lo, hi=hi, rates=rates)]
    return CobIdRules(services=services, notes=notes)


def bus_rules(profile: Profile) -> BusRules:
    name = profile.identity.product_name
    return BusRules(key=profile.id, name=name, short_name=name, node_range=profile.features.node_id_range,
                    baud_rates_kbit=list(profile.features.baud_rates_kbit), cob_ids=derived_cob_ids(profile))


class BusDevices:
    """Every loaded profile as a device of the planner: by its ``switches`` section (its key, aliases, the ids of
    the profiles that carry it) or by its profile id; EtherCAT slaves are known but not planned."""

    def __init__(self, profiles: Iterable[Profile]) -> None:
        every = list(profiles)
        self.switches = SwitchDevices(every)
        self._derived: dict[str, BusDevice] = {}
        self._other_bus: dict[str, Profile] = {}
        for profile in every:
            if profile.switches is not None or self.switches.find(profile.id) is not None:
                continue
            if _is_ethercat(profile):
                self._other_bus[profile.id.lower()] = profile
            elif profile.id.lower() not in self._derived:
                self._derived[profile.id.lower()] = BusDevice(bus_rules(profile), (profile.id,),
                                                              profile.identity.vendor_id)

    def all(self) -> list[BusDevice]:
        """The CANopen devices: those with switches first (by key), then the others (by profile id)."""
        with_switches = [BusDevice(d.spec, d.profile_ids, d.vendor_id) for d in self.switches.all()]
        return with_switches + [self._derived[key] for key in sorted(self._derived)]

    def not_on_can(self) -> list[Profile]:
        """Loaded profiles of another fieldbus (EtherCAT): no CAN plan applies to them."""
        return [self._other_bus[key] for key in sorted(self._other_bus)]

    def find(self, name: str) -> BusDevice | None:
        device = self.switches.find(name)
        if device is not None:
            return BusDevice(device.spec, device.profile_ids, device.vendor_id)
        return self._derived.get(name.strip().lower())

    def get(self, name: str) -> BusDevice:
        device = self.find(name)
        if device is not None:
            return device
        other = self._other_bus.get(name.strip().lower())
        if other is not None:
            raise NotOnCanBus(_("{device} is an EtherCAT slave: EtherCAT has no node id, bit rate or COB-ID plan (the "
                                "master addresses its slaves by their position in the line). Plan it in the EtherCAT "
                                "master's configuration, not on a CAN line.").format(
                                    device=other.identity.product_name))
        known = [d.spec.key for d in self.all()]
        raise UnknownProfile(_("No device '{name}' among the loaded profiles. Known devices: {known}.").format(
            name=name, known=", ".join(known) or _("none")))

    def switch_device(self, name: str) -> SwitchDevice:
        """The DIP-switch calculator's device of that name; a profile without a ``switches`` section is refused in
        words (it has no calculator, but the planner and the COB-ID table know it)."""
        found = self.switches.find(name)
        if found is not None:
            return found
        planned = self.get(name)  # an EtherCAT slave or an unknown name: refused there
        raise InvalidValue(_("{device} has no DIP-switch calculator: its profile has no 'switches' section. Its node "
                             "ids ({lo} … {hi}), bit rates and COB-IDs are in the network planner and the COB-ID "
                             "table.").format(device=planned.spec.name, lo=planned.spec.node_range[0],
                                              hi=planned.spec.node_range[1]))
