"""Graded assignments with nbgrader, built from the course notebooks (``tools/assignments.py``).

* :mod:`.source` - the instructor source: exercises found in a chapter notebook become nbgrader
  solution cells (reference solution between ``### BEGIN SOLUTION`` / ``### END SOLUTION``) and
  autograded test cells that run the chapter's checker and award a point per passed criterion.
* :mod:`.student_build` - ``course_helpers`` without ``solutions/``, and the check that no
  reference solution reaches the release.
* :mod:`.guarded` - nbgrader's Execute preprocessor with limits: output floods, a dead kernel
  and processes that outlive an exercise each cost that exercise its points, with a reason.
* :mod:`.isolation` - one student's run: its own environment, temporary folder and ROS domain,
  and the sweep afterwards that proves nothing of it is left.
* :mod:`.results` - the grade table (CSV) with a reason for every lost point.
* :mod:`.handin` - submissions made from an assignment: its reference, its starting code, any answers.
* :mod:`.verdict` - ``grade-all``'s check of a grade table: the reference earns every point, the
  starting code less on every exercise.
"""
