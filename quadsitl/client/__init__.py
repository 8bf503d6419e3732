"""The learner's end of the motor path: lockstep clients of a running simulator.

:class:`~.motor_client.MotorClient` flies one vehicle with HIL_ACTUATOR_CONTROLS;
:class:`~.fleet_client.FleetClient` flies every vehicle of a simulator process in
rounds of SET_ACTUATOR_CONTROL_TARGET. Both speak the words of :mod:`quadsitl.wire` and
read their answers with its :func:`~quadsitl.wire.answer.decode_answer`; neither needs
the simulator's server.
"""
