"""handrig in LeRobot: the logic behind the ``lerobot_teleoperator_handrig`` and
``lerobot_robot_handrig`` plugins (``plugins/``, docs/lerobot.md).

Nothing here imports LeRobot: the plugins' classes are LeRobot's config dataclasses and
device classes over these parts, so the logic is tested and typed with handrig's own.

* :mod:`.glove_stream`: the glove through handrig's pipeline in a thread of its own, its
  poses kept with their times, and the frame grid of a loop that asks once a frame;
* :mod:`.teleop`: the glove as a teleoperator (``handrig_glove``);
* :mod:`.hand`: a robot-hand preset as a robot (``handrig_leap``, ``handrig_orca``).
"""
