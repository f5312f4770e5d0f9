"""The simulator behind ``sim://``: a world model, motion with sliding contact and sensor models.

Plain Python with numpy and shapely, no Django and no other driver, so that the web tier (worlds
as stored documents), the ``sim://`` driver and the exercise checks all read the same world:

- :mod:`rhal.simulator.world`: the world document (JSON, format 1) as a validated ``World``;
- :mod:`rhal.simulator.worlds`: the built-in worlds (``boxes``, ``square``, ``maze``, ``line``,
  ``rooms``) and ``load()``;
- :mod:`rhal.simulator.physics`: a round differential-drive robot that slides along what it
  touches;
- :mod:`rhal.simulator.sensors`: the range cone, the sonar ring and the floor sensor.

docs/simulator.md describes the models.
"""
