"""The platoon's stepping: one control step of a platoon (`platoon`) or of many side by side in arrays
(`batch`), and what an episode leaves (`recording`, `trace`). Imports every other room of the model."""
