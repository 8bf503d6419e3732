"""Ground-station side tools: scripted flights, logging, replay."""
