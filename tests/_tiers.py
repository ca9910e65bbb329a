"""The slow tier: the tests that README's command leaves out and ``python -m pytest -q -m slow`` runs.

Every test that took over 5 seconds in one full run of the suite (2-core machine, 2026-12-01, the other core partly
busy; times below), and every test over 2.4 s in a quiet run of README's command (2026-12-03), besides those decorated ``@pytest.mark.slow`` in their files. Mostly the first test of a file to
compile a program (its followers then share it), finite-difference derivative checks, fits of whole measured data
sets, subprocesses of the command line and several processes at once. ``tests/conftest.py`` marks them at collection.
"""
# ruff: noqa: E501 - one test id a line, however long, so that the list reads as the suite names them

SLOW_TESTS = frozenset({
    "test_compact.py::test_no_blow_up_on_the_merl_grid",  # 21-28 s
    "test_baselines.py::test_curet_no_worse_than_scipy_and_backends_agree",  # 12 s
    "test_baselines.py::test_noise_free_data_fitted_back[ashikhmin-shirley]",  # 7 s
    "test_baselines.py::test_noise_free_data_fitted_back[blinn-phong]",  # 5 s
    "test_baselines.py::test_noise_free_data_fitted_back[cook-torrance]",  # 5 s
    "test_baselines.py::test_noise_free_data_fitted_back[ward-anisotropic]",  # 6 s
    "test_blender.py::test_blender_renders_the_glb_as_the_gltf_brdf[1.0-0.4-colour0-55.0]",  # 7 s
    "test_cli.py::test_main_job_runs_on_synthetic_default_and_says_so",  # 7 s
    "test_saved_programs_rewritten.py::test_saved_programs_removed_are_written_again_and_run",  # 13 s
    "test_cli_usability.py::test_fit_rows_one_per_material_and_channel_labelled_as_such",  # 7 s
    "test_compiled_programs.py::test_model_evaluation_and_selection_are_one_program_each",  # 12 s
    "test_data_merl.py::test_loaders_return_one_mask_row_when_every_lane_has_the_same_valid_bins",  # 8 s
    "test_data_nbrdf.py::test_call_masks_clamps_jits_and_vmaps",  # 9 s
    "test_data_nbrdf.py::test_fit_on_all_valid_merl_bins",  # 15 s
    "test_data_nbrdf.py::test_yellow_plastic_statistics",  # 5 s
    "test_data_rgl.py::test_export_to_merl_round_trip",  # 12 s
    "test_data_rgl.py::test_jit_vmap_and_below_horizon",  # 6 s
    "test_data_rgl.py::test_merl_grid_subsample_and_spec",  # 7 s
    "test_export.py::test_cli_export_every_format",  # 5 s
    "test_export_materialx_usd.py::test_materialx_file_validates_and_describes_the_fit",  # 15 s
    "test_export_standard_cli.py::test_export_mitsuba_xml_of_measured_data",  # 20 s
    "test_fit_images.py::test_excluded_pixels_saturated_nonfinite_off_object",  # 6 s
    "test_fit_images_standard.py::test_gltf_sphere_derivative_matches_finite_differences[two]",  # 9 s ([one] stays)
    "test_fit_images_standard.py::test_gltf_sphere_recovered[two]",  # 5 s ([one] stays)
    "test_fit_images.py::test_light_samples_render_like_the_renderer",  # 22 s
    "test_fit_images.py::test_neural_merl_from_images_close_to_direct_fit",  # 13 s
    "test_fit_images.py::test_refit_of_rendered_polynomial_recovers_coefficients[mixed]",  # 26 s
    "test_fit_images.py::test_refit_of_rendered_polynomial_recovers_coefficients[point]",  # 17 s
    "test_fit_images.py::test_shadowed_pixels_excluded",  # 5 s
    "test_fit_images_baselines.py::test_cook_torrance_sphere_recovered",  # 8 s
    "test_fit_images_baselines.py::test_several_light_samples_derivatives_match_finite_differences[environment]",  # 15 s
    "test_fit_images_baselines.py::test_several_light_samples_derivatives_match_finite_differences[two lights]",  # 15 s
    "test_fit_images_baselines.py::test_several_light_samples_recovered[environment]",  # 9 s
    "test_fit_images_baselines.py::test_several_light_samples_recovered[two lights]",  # 9 s
    "test_fit_images_cli.py::test_fit_images_command_recovers_the_api_fit",  # 12 s
    "test_grad_baselines.py::test_grad_under_jit_and_vmap_with_masks",  # 22 s
    "test_grad_baselines.py::test_jvp_and_grad_match_finite_differences[cook-torrance-which1]",  # 36 s
    "test_grad_baselines.py::test_jvp_and_grad_match_finite_differences[ward-which0]",  # 26 s
    "test_grad_render.py::test_environment_texels_fixed_pool",  # 12 s
    "test_grad_render.py::test_environment_with_shadows_and_indirect",  # 17 s
    "test_grad_render.py::test_polynomial_coefficients_point_and_directional",  # 7 s
    "test_inputs.py::test_nan_values_error_by_default_and_mask_on_request",  # 16 s
    "test_latency.py::test_cli_cache_is_hit_by_a_second_process",  # 13 s
    "test_latency.py::test_fit_command_parser_leaves_the_other_commands_unimported",  # 6 s
    "test_latency.py::test_streamed_fit_of_a_nearly_exact_polynomial_takes_the_refining_pass",  # 7 s
    "test_lstsq.py::test_several_fits_in_one_jit_do_not_deadlock",  # 8 s
    "test_mitsuba.py::test_fit_from_mitsuba_images_renders_held_out_light",  # 10 s
    "test_mitsuba.py::test_roughplastic_brdf_equals_mitsuba_eval",  # 9 s
    "test_photometric.py::test_fit_derivative_wrt_images_matches_finite_differences[opts0]",  # 5 s
    "test_photometric.py::test_fit_derivative_wrt_images_matches_finite_differences[opts1]",  # 9 s
    "test_photometric.py::test_fit_derivative_wrt_images_matches_finite_differences[opts2]",  # 9 s
    "test_photometric.py::test_fit_derivative_wrt_images_matches_finite_differences[opts3]",  # 9 s
    "test_published.py::test_fit_recovers_synthetic_data[sgd]",  # 10 s
    "test_render.py::test_force_all_effects_gives_identical_pixels",  # 6 s
    "test_render.py::test_tabulated_brdf_is_reciprocal_and_interpolates",  # 10 s
    "test_render_cli.py::test_render_command_writes_grid_and_psnr",  # 14 s
    "test_render_mis.py::test_brdf_sampled_indirect_bounces_agree_with_cosine_bounces",  # 14 s
    "test_render_mis.py::test_gradient_through_mis_environment_render_wrt_coefficients",  # 18 s
    "test_render_mis.py::test_mis_with_shadows_and_a_plane",  # 13 s
    "test_render_mis.py::test_modes_agree_and_mis_beats_cosine_on_a_glossy_sphere",  # 17 s
    "test_reproduce.py::test_reproduce_quick",  # 84 s
    "test_robust_data.py::test_all_zero_and_constant_materials_fitted_exactly",  # 7 s
    "test_robust_data.py::test_cayman_lacquer_peak_650_beside_1e_minus_4_fits_finite_float32_close",  # 7 s
    "test_robust_data.py::test_nan_and_inf_inside_values_error_names_the_argument_or_are_masked",  # 8 s
    "test_robust_data.py::test_nan_under_outer_jit_flags_nonfinite_values_lane_only",  # 7 s
    "test_robust_degree.py::test_degree_15_green_latex_float32_within_factor_of_float64",  # 10 s
    "test_robust_degree.py::test_degree_15_quarry_condition_reported_and_modest_float32_close_to_float64[ashikhmin-shirley]",  # 5 s
    "test_robust_degree.py::test_float32_tall_merl_design_keeps_full_rank",  # 8 s
    "test_robust_edge_inputs.py::test_component_constant_up_to_rounding_flagged_in_both_bases[ashikhmin-shirley]",  # 7 s
    "test_robust_edge_inputs.py::test_component_constant_up_to_rounding_flagged_in_both_bases[lafortune-anisotropic]",  # 8 s
    "test_robust_edge_inputs.py::test_component_constant_up_to_rounding_flagged_in_both_bases[lafortune]",  # 7 s
    "test_robust_edge_inputs.py::test_half_precision_values_fitted_in_float32[float16]",  # 5 s
    "test_robust_edge_inputs.py::test_models_scale_free_at_extreme_lengths",  # 6 s
    "test_robust_edge_inputs.py::test_nan_under_outer_jit_flagged_whatever_the_mask[no mask]",  # 11 s
    "test_robust_edge_inputs.py::test_nonfinite_mask_under_outer_jit_drops_the_sample",  # 5 s
    "test_robust_geometry.py::test_every_baseline_finite_at_degenerate_directions_through_the_fitted_model[openpbr-coat]",  # 7 s
    "test_robust_geometry.py::test_polynomial_finite_at_degenerate_directions_and_zero_below_horizon[ashikhmin-shirley]",  # 9 s
    "test_robust_geometry.py::test_polynomial_finite_at_degenerate_directions_and_zero_below_horizon[rusinkiewicz]",  # 5 s
    "test_robust_optimizer.py::test_best_of_starts_never_picks_a_nan_or_inf_start",  # 11 s
    "test_robust_optimizer.py::test_best_of_starts_skips_nonfinite_starts_on_both_backends_and_in_the_two_stage_path[jaxopt-1]",  # 22 s
    "test_robust_optimizer.py::test_best_of_starts_skips_nonfinite_starts_on_both_backends_and_in_the_two_stage_path[optimistix-2]",  # 5 s
    "test_robust_optimizer.py::test_curet_fits_at_range_limits_converge",  # 18 s
    "test_robust_optimizer.py::test_far_start_and_step_limit_reported_as_max_steps",  # 6 s
    "test_robust_optimizer.py::test_optimum_on_a_range_limit_converges_and_is_flagged[ashikhmin-shirley-params0-limit0]",  # 13 s
    "test_robust_optimizer.py::test_optimum_on_a_range_limit_converges_and_is_flagged[cook-torrance-params1-limit1]",  # 9 s
    "test_robust_properties.py::test_fit_invariant_to_sample_order",  # 7 s
    "test_robust_properties.py::test_pca_rotation_and_signs_stable",  # 6 s
    "test_robust_properties.py::test_symmetric_variable_sets_are_reciprocal",  # 17 s
    "test_robust_rank.py::test_fewer_samples_than_parameters_flagged_minimum_norm_interpolant",  # 6 s
    "test_robust_symmetry.py::test_reciprocal_at_any_pair_including_non_unit_and_below_horizon",  # 10 s
    "test_saved_models.py::test_baseline_fit_saves_and_loads_like_a_polynomial_fit[.npz]",  # 14 s
    "test_saved_models.py::test_model_kind_found_through_an_entry_point",  # 9 s (two fresh processes)
    "test_saved_models.py::test_fit_cli_fits_a_baseline_with_the_same_output_forms",  # 11 s
    "test_saved_models.py::test_polyjax_does_not_import_baselines",  # 8 s
    "test_saved_models.py::test_render_cli_model_fitted_to_other_materials_is_an_error",  # 19 s
    "test_saved_models.py::test_renderer_never_emits_negative_radiance",  # 5 s
    "test_scale.py::test_per_lane_directions_and_weights_any_block",  # 8 s
    "test_scale.py::test_per_lane_directions_differentiate",  # 14 s
    "test_scale.py::test_sharded_fit_on_8_devices",  # 14 s
    "test_scale.py::test_two_process_distributed_fit_writes_its_shards",  # 17 s
    "test_standard_models.py::test_joint_fit_derivative_matches_finite_differences",  # 13 s
    "test_standard_models.py::test_joint_fit_recovers_parameters[gltf-pbr-1]",  # 8 s
    "test_standard_models.py::test_joint_fit_recovers_parameters[principled-2]",  # 11 s
    "test_standard_openpbr_usd.py::test_fit_derivative_matches_finite_differences",  # 8 s
    "test_standard_openpbr_usd.py::test_grey_material_parameters_recovered[openpbr]",  # 26 s
    "test_standard_openpbr_usd.py::test_grey_material_parameters_recovered[usd-preview]",  # 8 s
    "test_stream_geometry.py::test_fit_after_a_kept_geometry_reuses_its_rows",  # 8 s
    "test_stream_geometry.py::test_kept_geometry_is_not_used_when_its_inputs_differ",  # 13 s
    "test_svbrdf.py::test_several_cameras_fit_differentiates",  # 8 s
    "test_svbrdf.py::test_several_cameras_observations_and_relight",  # 5 s
    "test_svbrdf.py::test_svbrdf_cli_cameras",  # 10 s
    "test_svbrdf.py::test_texels_recover_their_material",  # 6 s
    "test_tabulate.py::test_tabulate_baseline_fit_and_bad_input",  # 13 s
    "test_tabulate.py::test_tabulate_is_differentiable_in_the_model",  # 5 s
    "test_user_defects_2.py::test_readme_code_blocks_run_as_written",  # 110 s: the tour, photographs included
    "test_view.py::test_environment_map_lights_the_sphere_by_quadrature",  # 6 s
    "test_view.py::test_every_view_loads_offline_without_console_errors",  # 11 s
    "test_view.py::test_report_html_is_a_page_of_the_reports_fits",  # 10 s
    # over 2.4 s in a quiet full run of README's command (2 cores, 2026-12-03: 357 s, 768 tests)
    "test_baseline_saved_programs.py::test_second_process_loads_the_saved_program_bitwise",  # 13 s (2026-12-03)
    "test_logfit.py::test_log_fit_on_tall_rank_deficient_data_is_the_dense_fit",  # 8 s (2026-12-03)
    "test_view_inputs.py::test_capture_samples_photographs_and_relit_fit",  # 8 s (2026-12-03)
    "test_export_materialx_usd.py::test_usd_stage_validates_and_describes_the_fit",  # 8 s (2026-12-03)
    "test_view.py::test_sphere_matches_polyjax_render",  # 8 s (2026-12-03)
    "test_logfit.py::test_log_fit_on_tall_data_equals_the_dense_solves[alike]",  # 7 s (2026-12-03)
    "test_fit_images_standard.py::test_gltf_sphere_recovered[one]",  # 7 s (2026-12-03)
    "test_stream_geometry.py::test_kept_geometry_is_loaded_and_gives_the_same_fit[ashikhmin-shirley-degrees1]",  # 6 s (2026-12-03)
    "test_standard_mitsuba_rough.py::test_export_mitsuba_xml_roughconductor_renders_as_polyjax",  # 6 s (2026-12-03)
    "test_standard_mitsuba_rough.py::test_roughplastic_file_equals_mitsuba_eval[0.05-1.5]",  # 6 s (2026-12-03)
    "test_data_merl.py::test_loaded_grid_directions_are_taken_as_unit",  # 5 s (2026-12-03)
    "test_standard_mitsuba_rough.py::test_roughplastic_tables_derivative_matches_finite_differences",  # 5 s (2026-12-03)
    "test_fit_images_baselines.py::test_bad_scenes_and_images",  # 5 s (2026-12-03)
    "test_standard_mitsuba_rough.py::test_roughconductor_joint_fit_recovers_parameters",  # 5 s (2026-12-03)
    "test_grad_fit.py::test_fit_at_tied_pca_eigenvalues",  # 5 s (2026-12-03)
    "test_grad_fit.py::test_empty_lane_and_perfect_fit_do_not_poison_the_batch",  # 5 s (2026-12-03)
    "test_sampling.py::test_chi2_baselines[cook-torrance-normal]",  # 5 s (2026-12-03)
    "test_grad_fit.py::test_fit_jacobians_vmap_and_jit_agree",  # 5 s (2026-12-03)
    "test_export_standard_cli.py::test_export_gltf_of_a_saved_model_fits_it_back_exactly",  # 5 s (2026-12-03)
    "test_fit_images.py::test_image_rows_are_the_render",  # 5 s (2026-12-03)
    "test_published.py::test_fit_recovers_synthetic_data[abc]",  # 5 s (2026-12-03)
    "test_threads.py::test_one_lapack_thread_from_the_first_call_on_and_numpys_left_alone[loaded]",  # 5 s (2026-12-03)
    "test_user_defects_2.py::test_truncated_npz_model_is_a_data_format_error_naming_the_file",  # 4 s (2026-12-03)
    "test_stream_geometry.py::test_kept_geometry_of_a_loader_grid_serves_a_later_process",  # 4 s (2026-12-03)
    "test_baseline_saved_programs.py::test_saved_programs_keep_the_eager_rules",  # 4 s (2026-12-03)
    "test_export.py::test_merl_binary_round_trip[polynomial]",  # 4 s (2026-12-03)
    "test_compact_families.py::test_finite_non_negative_bounded_over_the_merl_grid[basis-config0]",  # 4 s (2026-12-03)
    "test_stream_geometry.py::test_geometry_from_a_sample_of_the_rows_is_a_householder_grade_qr[lafortune-4]",  # 4 s (2026-12-03)
    "test_logfit.py::test_log_fit_steps_lower_equation_11",  # 4 s (2026-12-03)
    "test_threads.py::test_one_lapack_thread_from_the_first_call_on_and_numpys_left_alone[fresh]",  # 4 s (2026-12-03)
    "test_baselines.py::test_noise_free_data_fitted_back[lafortune]",  # 4 s (2026-12-03)
    "test_sampling.py::test_density_positive_where_brdf_positive_even_for_negative_models",  # 4 s (2026-12-03)
    "test_user_defects.py::test_baselines_fit_under_jit_prepares_traced_inputs",  # 4 s (2026-12-03)
    "test_robust_optimizer.py::test_every_start_nonfinite_reported_and_parameters_not_nan",  # 4 s (2026-12-03)
    "test_logfit.py::test_log_fit_shared_program_equals_one_fit_per_solve[True]",  # 4 s (2026-12-03)
    "test_baselines.py::test_batched_over_materials_and_channels_and_status",  # 4 s (2026-12-03)
    "test_scale.py::test_per_lane_directions_equal_lane_alone",  # 4 s (2026-12-03)
    "test_saved_models.py::test_baseline_fit_saves_and_loads_like_a_polynomial_fit[.json]",  # 4 s (2026-12-03)
    "test_clamp.py::test_clamped_model_derivatives_match_finite_differences",  # 4 s (2026-12-03)
    "test_view_inputs.py::test_diligent_ball_photographs_on_the_page",  # 4 s (2026-12-03)
    "test_blender.py::test_blender_renders_the_glb_as_the_gltf_brdf[0.0-0.5-colour1-30.0]",  # 4 s (2026-12-03)
    "test_specs.py::test_solver_settings_fit_as_the_keyword_form",  # 4 s (2026-12-03)
    "test_sampling.py::test_vmap_over_views_and_gradient_wrt_view",  # 4 s (2026-12-03)
    "test_logfit.py::test_log_fit_shared_program_equals_one_fit_per_solve[False]",  # 3 s (2026-12-03)
    "test_grad_fit.py::test_rank_deficient_fit_has_finite_minimum_norm_derivatives",  # 3 s (2026-12-03)
    "test_stream_geometry.py::test_geometry_from_a_sample_of_the_rows_is_a_householder_grade_qr[ashikhmin-shirley-3]",  # 3 s (2026-12-03)
    "test_user_defects_2.py::test_svbrdf_warns_when_texel_fits_are_not_ok",  # 3 s (2026-12-03)
    "test_saved_models.py::test_render_cli_model_flag_takes_a_baseline_name_like_fit",  # 3 s (2026-12-03)
    "test_clamp.py::test_clamped_model_is_the_fit_inside_the_box_and_bounded_outside[rusinkiewicz-8-identity]",  # 3 s (2026-12-03)
    "test_grad_fit.py::test_check_grads_fit_polynomial_curet[u]",  # 3 s (2026-12-03)
    "test_photometric.py::test_float_capture_refits_exactly",  # 3 s (2026-12-03)
    "test_export.py::test_numpy_print_matches_model[lafortune]",  # 3 s (2026-12-03)
    "test_render_mis.py::test_white_furnace_lambertian[mis]",  # 3 s (2026-12-03)
    "test_baselines.py::test_noise_free_data_fitted_back[lafortune-anisotropic]",  # 3 s (2026-12-03)
    "test_fit_images.py::test_fit_is_linear_in_the_images_forward_mode",  # 3 s (2026-12-03)
    "test_baselines.py::test_noise_free_data_fitted_back[ward]",  # 3 s (2026-12-03)
    "test_grad_fit.py::test_jvp_with_cut_samples_not_nan",  # 3 s (2026-12-03)
    "test_logfit.py::test_log_fit_grad_matches_finite_differences",  # 3 s (2026-12-03)
    "test_clamp.py::test_clamped_model_is_the_fit_inside_the_box_and_bounded_outside[rusinkiewicz-6-log]",  # 3 s (2026-12-03)
    "test_logfit.py::test_rusinkiewicz_gradients_finite_at_theta_zero[rusinkiewicz]",  # 3 s (2026-12-03)
    "test_sampling.py::test_chi2_glossy_merl_polynomial[normal]",  # 3 s (2026-12-03)
    "test_baselines.py::test_noise_free_data_fitted_back[ward-duer]",  # 3 s (2026-12-03)
    "test_robust_edge_inputs.py::test_nan_under_outer_jit_flagged_whatever_the_mask[mask]",  # 3 s (2026-12-03)
    "test_grad_render.py::test_shadowed_scene_light_and_brdf",  # 3 s (2026-12-03)
    "test_specs.py::test_spec_fit_from_images_equals_the_keyword_form",  # 3 s (2026-12-03)
    "test_tabulate.py::test_tabulate_rgb_last_callable_on_the_merl_grid",  # 3 s (2026-12-03)
    "test_user_defects_2.py::test_a_foreign_baselines_package_is_named_in_the_error",  # 3 s (2026-12-03)
    "test_capture_textures.py::test_ggx_fit_recovers_the_lobe_it_was_made_from",  # 2 s (2026-12-03)
    "test_baselines.py::test_noise_free_data_fitted_back[oren-nayar]",  # 2 s (2026-12-03)
    "test_svbrdf.py::test_texture_shards_exr_round_trip",  # 2 s (2026-12-03)
    "test_latency.py::test_streamed_fit_equals_dense_fit[lafortune-degree0-legendre-False]",  # 2 s (2026-12-03)
})
