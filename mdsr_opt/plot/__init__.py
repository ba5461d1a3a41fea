"""Figures by stage (matplotlib). Every ``plot_*`` function takes ``ax=`` and returns the figure; importing
this package leaves the matplotlib backend alone and imports no study or scene code."""
