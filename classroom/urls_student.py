"""Routes of the students' pages: their exercises, an exercise, its Check, an attempt."""

from django.urls import path

from classroom import views_student as views

urlpatterns = [
    path("exercises/", views.exercise_list, name="student-exercise-list"),
    path("exercises/<int:pk>/", views.exercise_detail, name="student-exercise"),
    path("exercises/<int:pk>/start", views.exercise_start, name="student-exercise-start"),
    path("exercises/<int:pk>/check", views.exercise_check, name="student-exercise-check"),
    path("attempts/<int:pk>/", views.attempt_detail, name="attempt-detail"),
    path("attempts/<int:pk>/body", views.attempt_body, name="attempt-body"),
    path("attempts/<int:pk>/checklist", views.attempt_checklist, name="attempt-checklist"),
    path(
        "attempts/<int:pk>/replay/<int:variant>.json",
        views.attempt_replay,
        name="attempt-replay",
    ),
    path("attempts/<int:pk>/try", views.attempt_try, name="attempt-try"),
]
