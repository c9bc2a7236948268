"""CANopen (CiA 301) on a CAN bus: the master's network and SDO clients (canopen-based and the fast event-loop
path), NMT, heartbeat and node-guarding consumers, the trace decoder, and the SDO server the simulated nodes use.
Nothing here imports :mod:`drivebench.protocol.ethercat` (an import-linter contract)."""
