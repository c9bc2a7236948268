"""An independent CANopen master for simulator tests: canopen's Network and SDO client on a python-can virtual bus."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

import canopen
import pytest
from canopen.sdo.exceptions import SdoAbortedError


@contextmanager
def connected(channel: str) -> Iterator[canopen.Network]:
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel, receive_own_messages=False)
    try:
        yield network
    finally:
        network.disconnect()


def remote(master: canopen.Network, node_id: int) -> canopen.RemoteNode:
    node = canopen.RemoteNode(node_id, canopen.ObjectDictionary())
    master.add_node(node)
    node.sdo.RESPONSE_TIMEOUT = 2.0
    return node


def abort_code(action: Callable[[], object]) -> int:
    with pytest.raises(SdoAbortedError) as caught:
        action()
    return int(caught.value.code)
