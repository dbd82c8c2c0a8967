// The per-frame uniforms every program shares: the camera and the key light. Written once a frame
// into one buffer (base.Resources.begin_frame) and bound to FRAME_BINDING for all programs.
layout(std140) uniform Frame {
    mat4 u_view;
    mat4 u_proj;
    mat4 u_view_proj;     // u_proj * u_view
    vec3 u_eye;           // camera position, world space
    float u_ambient;
    vec3 u_light_dir;     // towards the light, world space, normalised
    float u_diffuse;
    vec2 u_viewport;      // pixels
    float u_specular;
};
