"""Development tooling for the CAN bridge: virtual CAN (User-Mode Linux), rigs, echo agents."""
