"""The robot and its cables: PSM kinematics, the cable bias (stretch, hysteresis, sag), motion timing, the arm's body.

``kinematics`` is pure maths (no PyBullet): the DH table, joint limits and forward
kinematics, and ``ik`` its closed-form inverse; ``bias`` holds the bias's magnitudes and
draws an instrument, ``cables`` turns commanded joints into the joints the cables really
produce, ``bias_statistics`` and ``bias_field`` measure (and plot) the bias over the
workspace; ``motion`` times straight-line moves; ``body`` is the arm in PyBullet.
"""
