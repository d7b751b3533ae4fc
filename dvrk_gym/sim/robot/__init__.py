"""The robot and its cables: PSM kinematics, the cable bias (stretch, hysteresis, sag), motion timing, the arm's body.

``kinematics`` is pure maths (no PyBullet); ``bias`` turns commanded joints into the joints
the cables really produce; ``motion`` times straight-line moves; ``body`` is the arm in
PyBullet; ``bias_field`` measures and plots the bias over the workspace.
"""
