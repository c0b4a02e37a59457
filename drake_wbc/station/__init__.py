"""The station the controller drives: the simulated robot in its scene.

The simulated station (drake_wbc.station.simulation) wraps a discrete
MultibodyPlant of the robot with its drivers (base velocity loop, arm
position servo), its sensors (the wrist F/T sensor, two 2-D LIDARs) and a
scripted scene (static obstacles, walking people, a person's hand on the
tool). Its ports carry the names the LCM hardware interface offers, so the
controller diagram is the same object against either.

May import the math layer and the robot; never the stages, the controller
or the hardware (the station is what the controller drives, not a part of
it).
"""
