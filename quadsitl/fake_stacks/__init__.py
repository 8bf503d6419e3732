"""Fake flight stacks flown from outside: quadsitl's own flight software behind a real
autopilot's simulator interface and MAVLink link, for tests without the autopilot."""
