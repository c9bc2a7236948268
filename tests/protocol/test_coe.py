"""CoE mailbox telegrams and SDO over a mailbox: the 8400 motec EtherCAT manual's telegrams byte for byte, the
ETG.8200 gateway frame, and client and server talking through an in-memory mailbox (expedited, normal, segmented,
abort, lost answers, toggle errors)."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from drivebench.errors import ProtocolError, SdoAbortError, SdoOutOfStepError, SdoStalledError, SdoTimeoutError
from drivebench.protocol.ethercat import coe
from drivebench.protocol.ethercat.coe_sdo import CoeSdoClient
from drivebench.protocol.ethercat.coe_server import Abort, CoeSdoServer
from drivebench.transport.ethercat_gateway import GatewayFormatError, gateway_frame, telegram_of
from tests.vectors import manual_coe as vectors


def test_the_manual_s_upload_response_of_c00039_1_decodes_to_0x0fa0() -> None:
    mailbox = coe.Mailbox.decode(vectors.UPLOAD_C00039_1_RESPONSE.telegram)
    assert (mailbox.type, mailbox.address, len(mailbox.data)) == (coe.MailboxType.COE, 0, 0x0A)
    message = coe.CoeMessage.decode(mailbox.data)
    assert message.service == coe.CoeService.SDO_RESPONSE
    frame = coe.parse_sdo(message.body)
    assert (frame.index, frame.subindex, frame.specifier, frame.expedited) == (0x5FD8, 1, 2, True)
    assert frame.expedited_data == bytes.fromhex("A00F") and int.from_bytes(frame.expedited_data, "little") == 4000


def test_our_telegrams_are_the_manual_s_bytes() -> None:
    assert coe.coe_mailbox(0, coe.CoeService.SDO_REQUEST, coe.upload_request(0x5FD8, 1)) == \
        vectors.UPLOAD_C00039_1_REQUEST.telegram
    assert coe.coe_mailbox(0, coe.CoeService.SDO_RESPONSE, coe.upload_response(0x5FD8, 1, b"\xa0\x0f", 112)) == \
        vectors.UPLOAD_C00039_1_RESPONSE.telegram
    mapping = (0x5C930110).to_bytes(4, "little")
    assert coe.coe_mailbox(0, coe.CoeService.SDO_REQUEST, coe.download_request(0x1600, 1, mapping, 112)) == \
        vectors.DOWNLOAD_1600_1_REQUEST.telegram
    assert coe.coe_mailbox(0, coe.CoeService.SDO_RESPONSE, coe.download_response(0x1600, 1)) == \
        vectors.DOWNLOAD_1600_1_RESPONSE.telegram
    assert coe.coe_mailbox(0, coe.CoeService.EMERGENCY, coe.emergency(0x1000, 0x01, bytes.fromhex("003181BC01"))) \
        == vectors.EMERGENCY_OPERATIONAL_QUIT.telegram


def test_the_manual_s_emergency_carries_the_lenze_error_number() -> None:
    message = coe.CoeMessage.decode(coe.Mailbox.decode(vectors.EMERGENCY_OPERATIONAL_QUIT.telegram).data)
    code, register, data = coe.parse_emergency(message.body)
    assert (message.service, code, register) == (coe.CoeService.EMERGENCY, 0x1000, 0x01)
    assert int.from_bytes(data[1:5], "little") == 0x01BC8131


def test_a_gateway_frame_is_the_telegram_behind_an_ethercat_mailbox_header() -> None:
    telegram = vectors.UPLOAD_C00039_1_REQUEST.telegram
    frame = gateway_frame(telegram)
    assert frame[:2] == (len(telegram) | 5 << 12).to_bytes(2, "little") == bytes.fromhex("1050")
    assert telegram_of(frame + b"\xff\xff") == telegram  # trailing bytes are not part of it
    with pytest.raises(GatewayFormatError, match="type 1"):
        telegram_of((len(telegram) | 1 << 12).to_bytes(2, "little") + telegram)
    with pytest.raises(GatewayFormatError, match="says 16 bytes"):
        telegram_of(frame[:10])


class Slave:
    """A dictionary of objects behind a CoE SDO server, reached through an in-memory mailbox."""

    def __init__(self, mailbox_size: int = 128) -> None:
        self.objects: dict[tuple[int, int], bytes] = {(0x5FD8, 1): b"\xa0\x0f", (0x29B2, 0): b"Mar 21 2005 12:31:21",
                                                      (0x1600, 1): bytes(4)}
        self.server = CoeSdoServer(0x03E9, self.read, self.write, mailbox_size=mailbox_size)
        self.writes = 0
        self.drop_answers = 0
        self.requests: list[bytes] = []

    def read(self, index: int, subindex: int) -> bytes:
        if (index, subindex) not in self.objects:
            raise Abort(0x06020000)
        return self.objects[index, subindex]

    def write(self, index: int, subindex: int, data: bytes) -> None:
        if index == 0x1600 and self.objects.get((0x29DA, 0)) == b"\x04":  # Safe-Operational: mapping is fixed
            raise Abort(0x08000022)
        self.writes += 1
        self.objects[index, subindex] = data

    def exchange(self, telegram: bytes, timeout_s: float) -> bytes | None:
        self.requests.append(telegram)
        answer = self.server.handle(telegram)
        if self.drop_answers:
            self.drop_answers -= 1
            return None
        return answer


@pytest.mark.parametrize("mailbox_size", [128, 24, 16])
@pytest.mark.parametrize("length", [0, 1, 4, 5, 7, 8, 20, 112, 113, 300])
def test_uploads_and_downloads_of_every_length_arrive_whole(mailbox_size: int, length: int) -> None:
    """Expedited (1…4 bytes), normal (fits the mailbox) and segmented (does not) transfers, both ways."""
    slave = Slave(mailbox_size)
    client = CoeSdoClient(slave.exchange, 0x03E9, mailbox_size=mailbox_size)
    data = bytes(range(256)) * 2
    client.download(0x2000, 1, data[:length])
    assert slave.objects[0x2000, 1] == data[:length]
    assert client.upload(0x2000, 1) == data[:length]


def test_a_long_string_is_read_through_a_normal_upload_response() -> None:
    slave = Slave()
    assert CoeSdoClient(slave.exchange, 0x03E9).upload(0x29B2, 0) == b"Mar 21 2005 12:31:21"
    mailbox = coe.Mailbox.decode(slave.server._last[2][0])  # type: ignore[index]
    assert len(mailbox.data) == 10 + 20  # the manual's "n = 10 + data bytes"


def test_an_abort_is_said_in_words_with_its_code() -> None:
    client = CoeSdoClient(Slave().exchange, 0x03E9)
    with pytest.raises(SdoAbortError) as caught:
        client.upload(0x2FFF, 0)
    assert caught.value.abort_code == 0x06020000
    assert "does not exist" in caught.value.detail and "0x2FFF" in caught.value.detail


def test_a_write_the_state_does_not_allow_is_refused_with_the_abort_of_the_slave() -> None:
    slave = Slave()
    slave.objects[0x29DA, 0] = b"\x04"
    with pytest.raises(SdoAbortError) as caught:
        CoeSdoClient(slave.exchange, 0x03E9).download(0x1600, 1, (0x5C930110).to_bytes(4, "little"))
    assert caught.value.abort_code == 0x08000022 and "present device state" in caught.value.abort_text


def test_a_lost_answer_is_asked_again_with_the_same_counter_and_done_once() -> None:
    slave = Slave()
    slave.drop_answers = 1
    CoeSdoClient(slave.exchange, 0x03E9, retries=2).download(0x2000, 0, b"\x01\x02")
    first, again = slave.requests
    assert first == again and coe.Mailbox.decode(first).counter != 0
    assert slave.writes == 1  # the slave answered the repetition without writing twice


def test_a_silent_slave_times_out_and_one_that_stops_mid_transfer_is_stalled() -> None:
    with pytest.raises(SdoTimeoutError, match="did not answer"):
        CoeSdoClient(lambda telegram, timeout: None, 7, timeout_s=0.01).upload(0x1000, 0)
    slave = Slave(mailbox_size=16)
    slave.objects[0x2000, 0] = bytes(40)
    answers = iter([True])

    def stops_after_the_start(telegram: bytes, timeout_s: float) -> bytes | None:
        return slave.exchange(telegram, timeout_s) if next(answers, False) else None

    with pytest.raises(SdoStalledError, match="after 0 of"):
        CoeSdoClient(stops_after_the_start, 0x03E9, mailbox_size=16, retries=0).upload(0x2000, 0)


def test_answers_out_of_step_are_refused() -> None:
    slave = Slave()

    def wrong_object(telegram: bytes, timeout_s: float) -> bytes | None:
        return coe.coe_mailbox(0x03E9, coe.CoeService.SDO_RESPONSE, coe.upload_response(0x5FD7, 1, b"\x01", 112))

    with pytest.raises(SdoOutOfStepError, match="answer for 0x5FD7"):
        CoeSdoClient(wrong_object, 0x03E9).upload(0x5FD8, 1)

    def mailbox_error(telegram: bytes, timeout_s: float) -> bytes | None:
        return coe.Mailbox(0x03E9, coe.MailboxType.ERROR, b"\x01\x00\x02\x00").encode()

    with pytest.raises(ProtocolError, match="protocol is not supported"):
        CoeSdoClient(mailbox_error, 0x03E9).upload(0x5FD8, 1)
    assert CoeSdoClient(slave.exchange, 0x03E9).upload(0x5FD8, 1) == b"\xa0\x0f"


@pytest.mark.parametrize("direction", ["upload", "download"])
def test_both_segment_loops_refuse_a_stall_a_repeated_segment_and_a_wrong_command(direction: str) -> None:
    """The checks every segment's answer goes through, for the upload and the download loop alike."""
    def transfer(answer: Callable[[int, bytes], bytes | None]) -> None:
        slave, exchanges = Slave(mailbox_size=16), iter(range(100))
        slave.objects[0x2000, 0] = bytes(40)

        def exchange(telegram: bytes, timeout_s: float) -> bytes | None:
            real = slave.exchange(telegram, timeout_s)
            assert real is not None
            return answer(next(exchanges), real)

        client = CoeSdoClient(exchange, 0x03E9, mailbox_size=16, retries=0)
        if direction == "upload":
            client.upload(0x2000, 0)
        else:
            client.download(0x2000, 0, bytes(40))

    with pytest.raises(SdoStalledError, match="after 1 of 6 segments"):  # 40 bytes, 7 to a 16-byte mailbox's segment
        transfer(lambda n, real: real if n < 2 else None)
    first_segment: list[bytes] = []

    def repeats_the_first_segment(n: int, real: bytes) -> bytes:
        if n == 1:
            first_segment.append(real)
        return first_segment[0] if n == 2 else real

    with pytest.raises(SdoOutOfStepError, match="toggle bit"):
        transfer(repeats_the_first_segment)
    with pytest.raises(SdoOutOfStepError, match="command specifier 3"):  # the command byte is the 9th
        transfer(lambda n, real: real if n != 1 else real[:8] + bytes([0x60 | real[8] & 0x1F]) + real[9:])
