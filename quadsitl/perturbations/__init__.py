"""The world's perturbations: what makes a flight differ from the nominal one.

Each is a model of its own, known to both the task envs and the simulator, and imports
only the physics: delay (:mod:`.delay`), domain randomisation (:mod:`.randomization`),
motor and sensor faults as task options (:mod:`.faults`, :mod:`.sensor_faults`), and a
vehicle's motors as fitted and failed in flight (:mod:`.motor_faults`).
"""
