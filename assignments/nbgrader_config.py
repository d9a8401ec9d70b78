"""nbgrader's configuration for the course's graded assignments (read by ``tools/assignments.py``).

The course directory is this folder: ``source/`` (generated from the notebooks by
``tools/assignments.py release``), ``release/``, ``submitted/``, ``autograded/``,
``feedback/`` and ``gradebook.db``; all of them are generated, none is committed.
"""

c = get_config()  # noqa: F821 - provided by traitlets when it reads this file

c.CourseDirectory.course_id = "ros2-course"

# The exercise cell keeps the student's starting code; the reference solution between
# ### BEGIN SOLUTION and ### END SOLUTION is removed without a stub.
c.ClearSolutions.code_stub = {"python": ""}

# Seconds a cell may run before nbgrader interrupts it (the slowest checker takes about 20 s on
# a loaded 2-core machine). tools/assignments.py grade --timeout overrides it.
c.Execute.timeout = 120
c.Execute.startup_timeout = 120
# No history file; the kernel's C-level output (ROS logging) goes to the grading log, not the
# cells, so a node's warning on stderr never costs points.
c.Execute.extra_arguments = ["--HistoryManager.hist_file=:memory:", "--IPKernelApp.capture_fd_output=False"]

# Feedback stays readable when a submission prints a lot or fails deep in a stack.
c.LimitOutput.max_lines = 300
c.LimitOutput.max_traceback = 60
