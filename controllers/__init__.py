"""Controllers for flexctl plants: one module per controller family."""
