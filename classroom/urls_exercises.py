"""Routes of a teacher's exercise pages (classroom.views_exercises)."""

from django.urls import path

from classroom import views_exercises as views

urlpatterns = [
    path("classroom/exercises/", views.exercise_list, name="exercise-list"),
    path("classroom/exercises/new", views.exercise_new, name="exercise-new"),
    path("classroom/exercises/<int:pk>/edit", views.exercise_edit, name="exercise-edit"),
    path("classroom/exercises/<int:pk>/recheck", views.exercise_recheck, name="exercise-recheck"),
    path("classroom/exercises/preview", views.text_preview, name="exercise-preview"),
    path("classroom/<int:group_id>/grid", views.class_grid, name="class-grid"),
]
