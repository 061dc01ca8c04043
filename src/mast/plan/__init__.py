"""Planning a beacon layout: predicted availability and precision along a drift."""
