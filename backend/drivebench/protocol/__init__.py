"""The protocol layer: what the tool says on a fieldbus. ``canopen/`` for CAN (CiA 301), ``ethercat/`` for EtherCAT
(CoE, ESM); shared here are the abort codes, data types, emergency records, the event-loop hand-off and the
:class:`~drivebench.protocol.fieldbus.Fieldbus` interface a session holds."""
