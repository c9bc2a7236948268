"""Drive semantics from profile data: CiA 402, the control and commissioning sections, what moves, faults."""
