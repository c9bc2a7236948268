"""Drive control: state machines, the safety guard with its keep-alive, motion, guided commissioning."""
