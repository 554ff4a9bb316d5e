"""DAgger's behaviour policy: the student acts, or the teacher with probability beta; the teacher always labels."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torch import nn


class TeacherStudentMixture(TensorDictModuleBase):
    """Writes ``action`` (the student's, or per swimmer and step with probability ``beta`` the teacher's) and
    ``teacher_action`` (the label) from the student's and the teacher's views of the same state.

    ``beta`` is set by the trainer before each batch; the draws come from ``generator`` alone (saved on resume).
    """

    def __init__(self, student: nn.Module, teacher: nn.Module, student_view: str, teacher_view: str, seed: int):
        super().__init__()
        self.student, self.teacher = student, teacher
        self.student_view, self.teacher_view = student_view, teacher_view
        self.in_keys = [student_view, teacher_view]
        self.out_keys = ["action", "teacher_action"]
        self.beta = 0.0
        self.generator = torch.Generator().manual_seed(seed)

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        a_student = self.student(td[self.student_view])
        a_teacher = self.teacher(td[self.teacher_view])
        action = a_student
        if self.beta > 0:
            use_teacher = torch.rand(a_student.shape[0], 1, generator=self.generator) < self.beta
            action = torch.where(use_teacher.to(a_student.device), a_teacher, a_student)
        return td.set("action", action).set("teacher_action", a_teacher)
