"""EtherCAT: CoE mailbox telegrams (SDO, SDO information, emergencies), the state machine (ESM) and the master's
object dictionary, the segment behind a mailbox gateway (ETG.8200) and the direct master on a network card, each
offered to a session as a :class:`~drivebench.protocol.fieldbus.Fieldbus`."""
