"""Survey missions: QGroundControl and Mission Planner files written from a plan, read back and
flown in PyFlyt, and the checks of a site before planning."""
