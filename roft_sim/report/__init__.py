"""Reports: tables (text, Markdown, CSV, LaTeX), plots drawn with OpenCV, overlay videos."""
