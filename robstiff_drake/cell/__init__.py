"""The cell's real inputs and outputs: the Net F/T's RDT protocol, ABB's
EGM protocol, the compensator process and the simulated cell's network
side.  Plain Python; no Drake."""
