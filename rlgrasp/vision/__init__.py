"""Policies that see through a camera: image models and teacher-student distillation."""
