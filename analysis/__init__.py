"""Pictures and curves to numbers (paper section 4.2)."""
