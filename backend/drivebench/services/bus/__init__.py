"""A session's bus: sessions and their nodes, the transport seam (CAN or EtherCAT), bus health."""
