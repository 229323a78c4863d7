# Viewer rules (issue 17): filled in by the viewer work.
