"""The direct master's transport with the real pysoem (SOEM) on this machine: its bus spec, and each reason it cannot
run, in words. This machine has no EtherCAT card and no slave: SOEM is opened for real on ``lo`` (raw frames go out
and nobody answers) and on a card that does not exist; the missing privilege is a real process without CAP_NET_RAW
(``setpriv``); a missing pysoem is an import made to fail (``sys.modules['pysoem'] = None``)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

from drivebench.errors import BusSpecError, ProtocolError, TransportError
from drivebench.protocol.ethercat.master import DirectNetwork
from drivebench.services.bus.fieldbus import parse_spec
from drivebench.transport.ethercat_soem import DirectSpec, may_use_raw_sockets, network_cards, open_link

pysoem = pytest.importorskip("pysoem")
PRIVILEGED = pytest.mark.skipif(not may_use_raw_sockets(), reason="needs CAP_NET_RAW (root) to open raw sockets")
NO_NET_RAW = ["setpriv", "--inh-caps=-net_raw", "--bounding-set=-net_raw"]


def test_bus_spec_names_the_card() -> None:
    spec = parse_spec(" ethercat:enp3s0.100 ")
    assert spec == DirectSpec("enp3s0.100")
    assert (str(spec), spec.interface, spec.channel, spec.bitrate) == ("ethercat:enp3s0.100", "ethercat",
                                                                       "enp3s0.100", 100_000_000)
    for wrong in ("ethercat:", "ethercat:eth 1", "ethercat:eth1/2", f"ethercat:{'x' * 33}"):
        with pytest.raises(BusSpecError, match=r"is not a network card: write ethercat:NIC, e\.g\. ethercat:eth1"):
            parse_spec(wrong)


def test_without_pysoem_the_extra_is_named(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "pysoem", None)  # as if not installed: importing it fails
    with pytest.raises(TransportError) as refused:
        open_link(DirectSpec("lo"), 0.5)
    assert str(refused.value) == ("The direct EtherCAT master needs pysoem: install DriveBench with its extra "
                                  "(pip install 'drivebench[ethercat]'), or reach the slaves through a master's "
                                  "mailbox gateway (ethercat-mbg:HOST).")


@PRIVILEGED
def test_an_unknown_card_is_named_with_the_cards_present() -> None:
    with pytest.raises(TransportError) as refused:
        open_link(DirectSpec("eth9"), 0.5)
    assert "lo" in network_cards()
    assert str(refused.value) == (f"This computer has no network card 'eth9'; it has {', '.join(network_cards())} "
                                  "(see ip link).")


@PRIVILEGED
def test_soem_on_a_card_without_slaves_finds_none_in_words() -> None:
    spec = DirectSpec("lo")
    network = DirectNetwork(spec, open_link(spec, 0.2), sdo_timeout_s=0.2, sdo_retries=0)
    try:
        assert network.link.scan() == []  # SOEM's config_init: nobody answered the broadcast read
        with pytest.raises(ProtocolError) as none:
            network.scan()
        assert str(none.value) == ("No EtherCAT slave answered on lo: check the cable from this card to the first "
                                   "slave's IN port, the slaves' power, and that no other master uses the card.")
        assert network.link_text is None  # lo has a carrier
    finally:
        network.close()


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("setpriv") is None,
                    reason="dropping CAP_NET_RAW from a process needs root and setpriv")
def test_without_cap_net_raw_soem_cannot_open_and_the_refusal_says_how_to_grant_it() -> None:
    script = """
from drivebench.errors import TransportError
from drivebench.transport.ethercat_soem import DirectSpec, SoemLink, open_link
import pysoem
for attempt in (lambda: SoemLink(DirectSpec("lo"), pysoem), lambda: open_link(DirectSpec("lo"), 0.5)):
    try:
        attempt()
    except TransportError as exc:
        print(exc)
"""
    done = subprocess.run([*NO_NET_RAW, sys.executable, "-c", script], capture_output=True, text=True, timeout=60,
                          check=True)
    soem, refusal = done.stdout.splitlines()
    assert soem == "pysoem could not open lo for raw EtherCAT frames: could not open interface lo"
    assert refusal == ("The direct EtherCAT master sends raw Ethernet frames on lo: run DriveBench as root or give "
                       "its Python CAP_NET_RAW (setcap cap_net_raw+ep), or reach the slaves through a master's "
                       "mailbox gateway (ethercat-mbg:HOST).")

