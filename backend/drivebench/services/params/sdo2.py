"""The second SDO channel: a read-all spreads one node's reads over its SDO channels, with the profile's first
additional SDO server (its ``sdo_channels`` section) switched on where that is safe."""

from __future__ import annotations

from drivebench.errors import ProtocolError, SdoAbortError, SdoTimeoutError
from drivebench.i18n import N_, Text
from drivebench.protocol.canopen.network import NodeClient
from drivebench.services.bus.sessions import Session, SessionNode
from drivebench.services.params.session_part import NodeChannels, on_bus, service
from drivebench.services.params.write_context import WriteContext
from drivebench.services.params.writes import send_logged


def _sdo2_check_blocking(session: Session, node: SessionNode) -> tuple[NodeChannels, tuple[int, int] | None]:
    """The node's channel state, with SDO2 in use where it is on in the node already; where the profile's first
    additional SDO server (its ``sdo_channels`` section) is off and safe to use, the COB-IDs to switch it on with."""
    state = service(session)
    channels = state.channels.setdefault(node.node_id, NodeChannels())
    if channels.active:
        return channels, None
    catalog = node.catalog
    profile = node.profile
    if (not state.settings.use_sdo2 or catalog is None or profile is None or not profile.sdo_channels
            or profile.features.transport != "canopen"):
        return channels, None
    extra = profile.sdo_channels[0]
    index = extra.parameter_index
    rx_item, tx_item = catalog.by_address(index, 1), catalog.by_address(index, 2)
    if rx_item is None or tx_item is None or not rx_item.entry.access.writable:
        return channels, None
    clash = extra.clashes_with(node.node_id)
    if node.node_id > extra.max_node_id or clash in session.nodes:
        channels.note = Text(N_("SDO{number} not used on node {node}: its identifiers would be node {other}'s SDO1"),
                              number=extra.number, node=node.node_id, other=clash)
        return channels, None
    client = session.client(node.node_id).sdo_servers
    if client is None:  # an EtherCAT slave has one mailbox
        return channels, None
    rx, tx = (int.from_bytes(client.upload(index, sub, channel=1)[:4], "little") for sub in (1, 2))
    if rx & 0x80000000 or tx & 0x80000000 or not rx or not tx:
        return channels, extra.cob_ids(node.node_id)
    _use_sdo2(client, channels, rx, tx)
    return channels, None


def _use_sdo2(client: NodeClient, channels: NodeChannels, rx: int, tx: int) -> None:
    if channels.sdo2 is None:
        channels.sdo2 = client.add_channel(rx & 0x7FF, tx & 0x7FF)
    elif channels.sdo2 not in client.channels:
        client.channels.append(channels.sdo2)
    channels.active = True


async def _activate_sdo2(session: Session, node: SessionNode, ctx: WriteContext) -> NodeChannels:
    """Switch on the profile's first additional SDO server where that is safe (the writes in the audit log with the
    origin of whoever reads: a read-all, a parameter-set download reading the values before it writes)."""
    channels, switch_on = await on_bus(lambda: _sdo2_check_blocking(session, node))
    if switch_on is None or node.profile is None:
        return channels
    extra = node.profile.sdo_channels[0]
    rx, tx = switch_on
    for sub, cob_id in ((1, rx), (2, tx)):  # client -> server first, then server -> client (the manuals' 0x1201)
        await send_logged(session, node.node_id, extra.parameter_index, sub, cob_id.to_bytes(4, "little"),
                          ctx=ctx, verify=True)
    channels.note = Text(N_("SDO{number} activated on node {node} ({rx}/{tx}, not saved)"), number=extra.number,
                          node=node.node_id, rx=f"0x{rx:03X}", tx=f"0x{tx:03X}")
    client = session.client(node.node_id).sdo_servers
    if client is not None:  # checked by _sdo2_check_blocking
        _use_sdo2(client, channels, rx, tx)
    return channels


async def sdo_channels(session: Session, node: SessionNode, ctx: WriteContext) -> list[int]:
    """The channel numbers to spread reads over (SDO2 activated first where possible; asked twice when it times
    out, as one late answer on a busy machine would otherwise halve the read-all's speed)."""
    for attempt in range(2):
        try:
            channels = await _activate_sdo2(session, node, ctx)
        except SdoTimeoutError:
            if attempt:
                return [1]
            continue
        except (SdoAbortError, ProtocolError):
            return [1]
        return [1, 2] if channels.active else [1]
    return [1]

