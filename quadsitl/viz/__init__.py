"""Rerun views of flights: the scene (:mod:`.scene`), where a recording is shown
(:mod:`.viewer`), MAVLink messages as samples (:mod:`.flight_view`) and the row-by-row
logger shared by the live views (:mod:`.live`); and, without Rerun, the envs'
``rgb_array`` frames (:mod:`.raster`)."""
