"""What MAST's results look like to people and to other programs: the JSON record and
the survey-style text report of a fix (:mod:`mast.report.record`), and the kit every
HTML report is made with (:mod:`mast.report.html`).

Below the applications (``runs``, ``live``, ``cloud``, ``plan``) and above the pipeline:
it reads a :class:`~mast.pipeline.locator.Fix`, never runs one.
"""
