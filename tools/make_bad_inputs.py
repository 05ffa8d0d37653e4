#!/usr/bin/env python3
"""Writes the bad-input corpus tests/bad_inputs/ (run from the repo root, with a built
longreach: LONGREACH_BIN, default target/debug/longreach, makes the journals).
Edit the cases here and run it again; tests/cli/bad_inputs.rs runs them."""
import os, shutil, json, sys
ROOT = 'tests/bad_inputs'
# The binary is run from temporary folders: its path is made absolute here, and a
# missing one stops the script before it touches the corpus.
BIN = os.path.abspath(os.environ.get('LONGREACH_BIN', 'target/debug/longreach'))
if not os.access(BIN, os.X_OK):
    sys.exit(f'{BIN}: no longreach binary; build it (cargo build) or set LONGREACH_BIN')
cases = []

def q(s):
    return json.dumps(s)

def case(group, name, files, args, exit, contains, keep=(), stdout_closed=False, written=None):
    d = os.path.join(ROOT, group, name)
    if os.path.exists(d):
        shutil.rmtree(d)
    os.makedirs(d)
    for rel, text in files.items():
        p = os.path.join(d, rel)
        os.makedirs(os.path.dirname(p) or d, exist_ok=True)
        if text is None:
            os.makedirs(p, exist_ok=True)
        elif isinstance(text, bytes):
            open(p, 'wb').write(text)
        else:
            open(p, 'w').write(text)
    t = 'args = [' + ', '.join(q(a) for a in args) + ']\n'
    t += f'exit = {exit}\n'
    t += 'contains = [' + ', '.join(q(c) for c in contains) + ']\n'
    if keep:
        t += 'keep = [' + ', '.join(q(k) for k in keep) + ']\n'
    if stdout_closed:
        t += 'stdout_closed = true\n'
    if written:
        t += 'written = { ' + ', '.join(f'{q(k)} = [' + ', '.join(q(w) for w in v) + ']' for k, v in written.items()) + ' }\n'
    open(os.path.join(d, 'case.toml'), 'w').write(t)
    cases.append(d)

if os.path.exists(ROOT):
    shutil.rmtree(ROOT)

# ---------------------------------------------------------------- bode scenarios
# The paper's rig: the [rig] table of Bode scenarios and sweep datasets alike.
RIG = '''[rig]
rope = "dyneema2"
rope_length_m = 15.2
input_radius_m = 0.025
output_radius_m = 0.025
output_inertia_kg_m2 = 0.0284
output_damping_n_m_s = 0.05
relay_pulleys = 3
relay_radius_m = 0.025
tensioner = "constant_force"
'''
BODE = '''title = "tiny"
kind = "bode"

''' + RIG + '''prestretch_n = 490.0

[sweep]
mean_tensions_n = [98.0]
amplitude_deg = 4.5
frequencies_hz = [1.5, 2.5, 3.5]
settle_s = 0.5
min_cycles = 1
min_hold_s = 0.2

[simulation]
dt_s = 0.002
'''

def bode(name, old, new, exit, contains, extra_args=(), files=None, **kw):
    assert old in BODE, old
    f = {'bode.toml': BODE.replace(old, new, 1)}
    if files:
        f.update(files)
    case('scenario', name, f, ['bode', 'bode.toml', '--quiet', *extra_args], exit, contains, **kw)

bode('toml_syntax', 'settle_s = 0.5', 'settle_s = = 0.5', 2, ['bode.toml:20', 'syntax', 'fix'])
bode('type_error_names_the_key', 'settle_s = 0.5', 'settle_s = "long"', 2, ['field `sweep.settle_s`', 'fix'])
bode('unknown_field', 'settle_s = 0.5', 'settle_s = 0.5\nsettle = 1.0', 2, ['settle', 'fix'])
bode('missing_field', 'mean_tensions_n = [98.0]\n', '', 2, ['mean_tensions_n', 'fix'])
bode('empty_tensions', 'mean_tensions_n = [98.0]', 'mean_tensions_n = []', 2, ['sweep.mean_tensions_n', 'fix'])
bode('empty_frequencies', 'frequencies_hz = [1.5, 2.5, 3.5]', 'frequencies_hz = []', 2, ['frequencies_hz', 'fix'])
bode('negative_frequency', 'frequencies_hz = [1.5, 2.5, 3.5]', 'frequencies_hz = [1.5, -2.5, 3.5]', 2, ['frequencies_hz', 'fix'])
bode('nan_frequency', 'frequencies_hz = [1.5, 2.5, 3.5]', 'frequencies_hz = [1.5, nan, 3.5]', 2, ['frequencies_hz', 'fix'])
bode('descending_frequencies_run', 'frequencies_hz = [1.5, 2.5, 3.5]', 'frequencies_hz = [3.5, 2.5, 2.0, 1.5]', 0, ['resonance'])
bode('repeated_frequencies_run', 'frequencies_hz = [1.5, 2.5, 3.5]', 'frequencies_hz = [1.5, 2.5, 2.5, 3.5]', 0, ['resonance'])
bode('settle_huge', 'settle_s = 0.5', 'settle_s = 1e12', 2, ['sweep.settle_s', 'limit', 'fix'])
bode('settle_negative', 'settle_s = 0.5', 'settle_s = -1.0', 2, ['settle_s', 'fix'])
bode('settle_inf', 'settle_s = 0.5', 'settle_s = inf', 2, ['settle_s', 'fix'])
bode('hold_huge', 'min_hold_s = 0.2', 'min_hold_s = 1e12', 2, ['limit', 'fix'])
bode('cycles_zero', 'min_cycles = 1', 'min_cycles = 0', 2, ['min_cycles', 'fix'])
bode('cycles_overflow', 'min_cycles = 1', 'min_cycles = 40000000000', 2, ['min_cycles', 'fix'])
bode('cycles_huge', 'min_cycles = 1', 'min_cycles = 100000000', 2, ['limit', 'fix'])
bode('frequency_tiny', 'frequencies_hz = [1.5, 2.5, 3.5]', 'frequencies_hz = [1e-300, 2.5]', 2, ['limit', 'fix'])
bode('dt_zero', 'dt_s = 0.002', 'dt_s = 0.0', 2, ['simulation.dt_s', 'fix'])
bode('dt_too_large', 'dt_s = 0.002', 'dt_s = 0.1', 2, ['simulation.dt_s', 'fix'])
bode('dt_nan', 'dt_s = 0.002', 'dt_s = nan', 2, ['simulation.dt_s', 'fix'])
bode('above_nyquist', 'frequencies_hz = [1.5, 2.5, 3.5]\nsettle_s = 0.5\nmin_cycles = 1\nmin_hold_s = 0.2\n\n[simulation]\ndt_s = 0.002', 'frequencies_hz = [1.5, 2.5, 12.0]\nsettle_s = 0.5\nmin_cycles = 1\nmin_hold_s = 0.2\n\n[simulation]\ndt_s = 0.05', 2,
     ['sweep.frequencies_hz.2', 'Nyquist', 'fix'], files=None)
STIFF = '''[rig.rope]
tensile_strength_n = 3000.0
k1 = 5e9
'''
def stiff(text, dt, k1='5e9'):
    t = text.replace('rope = "dyneema2"\n', '').replace('prestretch_n = 490.0\n', 'prestretch_n = 490.0\n' + STIFF)
    return t.replace('dt_s = 0.002', f'dt_s = {dt}').replace('k1 = 5e9', f'k1 = {k1}')
case('scenario', 'stiff_rope_coarse_step', {'bode.toml': stiff(BODE, 0.05)}, ['bode', 'bode.toml', '--quiet'], 2,
     ['simulation.dt_s', 'fastest mode', 'fix'])
case('scenario', 'stiff_rope_warning', {'bode.toml': stiff(BODE, 0.0005, '5e7')}, ['bode', 'bode.toml', '--quiet', '--json', 'out.json'], 0,
     ['warning', 'fastest mode', 'dt_s <='], written={'out.json': ['"warnings"', 'fastest mode']})
bode('steps_per_period_warning', 'dt_s = 0.002', 'dt_s = 0.02', 0, ['warning', 'steps per period'])
bode('both_amplitudes', 'amplitude_deg = 4.5', 'amplitude_deg = 4.5\namplitude_rad = 0.1', 2, ['amplitude', 'e.g.'])
bode('negative_amplitude', 'amplitude_deg = 4.5', 'amplitude_deg = -4.5', 2, ['amplitude_deg', 'fix'])
bode('unknown_rope', 'rope = "dyneema2"', 'rope = "dyneema9"', 2, ['rope', 'dyneema9', 'fix'])
bode('negative_length', 'rope_length_m = 15.2', 'rope_length_m = -15.2', 2, ['rope_length_m', 'fix'])
bode('zero_inertia', 'output_inertia_kg_m2 = 0.0284', 'output_inertia_kg_m2 = 0.0', 2, ['output_inertia_kg_m2', 'fix'])
bode('negative_tension', 'mean_tensions_n = [98.0]', 'mean_tensions_n = [-98.0]', 2, ['mean_tensions_n', 'fix'])
bode('wrong_kind', 'kind = "bode"', 'kind = "arm"', 2, ['kind', 'fix'])
bode('relay_pulleys_negative', 'relay_pulleys = 3', 'relay_pulleys = -3', 2, ['relay_pulleys', 'fix'])
bode('unknown_tensioner', 'tensioner = "constant_force"', 'tensioner = "spring"', 2, ['tensioner', 'fix'])
bode('unknown_law', 'rope = "dyneema2"', 'rope = "dyneema2"\nlaw = "plastic"', 2, ['law', 'fix'])
case('scenario', 'missing_file', {}, ['bode', 'nothere.toml'], 2, ['nothere.toml', 'check the path'])
case('scenario', 'not_utf8', {'bode.toml': b'\xff\xfe\x00garbage\x00'}, ['bode', 'bode.toml'], 2, ['bode.toml', 'fix'])
case('scenario', 'empty_file', {'bode.toml': ''}, ['bode', 'bode.toml'], 2, ['bode.toml', 'missing field', 'fix'])
case('scenario', 'a_folder_as_file', {'bode.toml': None}, ['bode', 'bode.toml'], 2, ['bode.toml', 'fix'])

# ---------------------------------------------------------------- outputs of bode
case('output', 'json_into_a_folder', {'bode.toml': BODE, 'res.json/keep.txt': 'mine'},
     ['bode', 'bode.toml', '--quiet', '--json', 'res.json'], 2, ['res.json', 'existing folder', 'fix'], keep=['res.json/keep.txt'])
case('output', 'csv_into_missing_folder', {'bode.toml': BODE},
     ['bode', 'bode.toml', '--quiet', '--csv', 'nodir/res.csv'], 2, ['res.csv', 'fix'])
case('output', 'png_into_a_folder', {'bode.toml': BODE, 'plot.png/keep.txt': 'mine'},
     ['bode', 'bode.toml', '--quiet', '--png', 'plot.png'], 2, ['plot.png', 'existing folder', 'fix'], keep=['plot.png/keep.txt'])
case('output', 'bode_closed_stdout', {'bode.toml': BODE}, ['bode', 'bode.toml'], 141, [], stdout_closed=True)
case('output', 'ropes_closed_stdout', {}, ['ropes'], 141, [], stdout_closed=True)

# ---------------------------------------------------------------- arm scenarios (run)
URDF = open('robots/rig/rig.urdf').read()
ARM = '''[arm]
urdf = "robot.urdf"

[sim]
dt_s = 0.001
duration_s = 0.2
output_every = 10
residual_window_s = 0.1

[transmission_defaults]
rope = "dyneema2"
law = "four_element"
tensioner = "fixed"

[transmission_defaults.motor]
mode = "servo"
damping_n_m_s = 1.0
gravity_feedforward = true

[[transmission]]
joint = "phi"
joint_radius_m = 0.025
ropes_in_parallel = 1
preload_n = 100.0
motor.inertia_kg_m2 = 0.01
motor.kp_n_m_per_rad = 10.0
motor.kd_n_m_s_per_rad = 1.0
motor.torque_limit_n_m = 50.0
command = { kind = "step", to_rad = 0.1, at_s = 0.05 }
'''

def arm(name, old, new, exit, contains, extra_args=(), files=None, urdf=URDF, group='arm', **kw):
    assert old in ARM, old
    f = {'arm.toml': ARM.replace(old, new, 1), 'robot.urdf': urdf}
    if files:
        f.update(files)
    case(group, name, f, ['run', 'arm.toml', *extra_args], exit, contains, **kw)

arm('runs', 'duration_s = 0.2', 'duration_s = 0.2', 0, ['tip'])
arm('duration_huge', 'duration_s = 0.2', 'duration_s = 1e12', 2, ['sim.duration_s', 'limit', 'fix'])
arm('duration_negative', 'duration_s = 0.2', 'duration_s = -1.0', 2, ['sim.duration_s', 'fix'])
arm('duration_type', 'duration_s = 0.2', 'duration_s = "0.2"', 2, ['field `sim.duration_s`', 'fix'])
arm('dt_zero', 'dt_s = 0.001', 'dt_s = 0.0', 2, ['sim.dt_s', 'fix'])
arm('step_at_nan', 'at_s = 0.05', 'at_s = nan', 2, ['at_s', 'fix'])
arm('step_at_negative', 'at_s = 0.05', 'at_s = -1.0', 2, ['at_s', 'fix'])
arm('residual_window_negative', 'residual_window_s = 0.1', 'residual_window_s = -1.0', 2, ['residual_window_s', 'fix'])
arm('output_every_zero', 'output_every = 10', 'output_every = 0', 2, ['output_every', 'fix'])
arm('unknown_joint', 'joint = "phi"', 'joint = "nope"', 2, ['nope', 'fix'])
arm('unknown_command', 'kind = "step"', 'kind = "jump"', 2, ['jump', 'fix'])
arm('unknown_rope', 'rope = "dyneema2"', 'rope = "dyneema9"', 2, ['dyneema9', 'fix'])
arm('negative_preload', 'preload_n = 100.0', 'preload_n = -100.0', 2, ['preload_n', 'fix'])
arm('initial_wrong_length', 'urdf = "robot.urdf"', 'urdf = "robot.urdf"\ninitial_q_rad = [0.0, 1.0]', 2, ['initial_q_rad', 'fix'])
arm('unknown_sim_key', 'output_every = 10', 'output_every = 10\nsteps = 5', 2, ['steps', 'fix'])
arm('urdf_missing', 'urdf = "robot.urdf"', 'urdf = "nothere.urdf"', 2, ['nothere.urdf', 'fix'])
arm('trapezoid_zero_velocity', 'command = { kind = "step", to_rad = 0.1, at_s = 0.05 }',
    'command = { kind = "trapezoid", to_rad = 0.1, max_velocity_rad_s = 0.0, max_accel_rad_s2 = 1.0 }', 2, ['max_velocity_rad_s', 'fix'])
arm('sine_start_nan', 'command = { kind = "step", to_rad = 0.1, at_s = 0.05 }',
    'command = { kind = "sine", amplitude_rad = 0.1, frequency_hz = 1.0, start_s = nan }', 2, ['start_s', 'fix'])
CSVCMD = 'command = { kind = "csv", file = "cmd.csv", column = "angle_rad" }'
arm('csv_command_missing_file', 'command = { kind = "step", to_rad = 0.1, at_s = 0.05 }', CSVCMD, 2, ['cmd.csv', 'fix'])
arm('csv_command_bad_cell', 'command = { kind = "step", to_rad = 0.1, at_s = 0.05 }', CSVCMD, 2, ['cmd.csv:3', 'angle_rad', 'fix'],
    files={'cmd.csv': 'time_s,angle_rad\n0.0,0.0\n0.1,abc\n'})
arm('csv_command_nan', 'command = { kind = "step", to_rad = 0.1, at_s = 0.05 }', CSVCMD, 2, ['cmd.csv:4', 'finite', 'fix'],
    files={'cmd.csv': 'time_s,angle_rad\n0.0,0.0\n0.1,0.1\n0.2,NaN\n'})
arm('csv_command_no_time', 'command = { kind = "step", to_rad = 0.1, at_s = 0.05 }', CSVCMD, 2, ['time_s', 'fix'],
    files={'cmd.csv': 't,angle_rad\n0.0,0.0\n'})
arm('csv_command_ragged', 'command = { kind = "step", to_rad = 0.1, at_s = 0.05 }', CSVCMD, 2, ['cmd.csv:3', 'fix'],
    files={'cmd.csv': 'time_s,angle_rad\n0.0,0.0\n0.1,0.1,7\n'})
arm('csv_command_time_backwards', 'command = { kind = "step", to_rad = 0.1, at_s = 0.05 }', CSVCMD, 2, ['cmd.csv', 'fix'],
    files={'cmd.csv': 'time_s,angle_rad\n0.0,0.0\n0.2,0.1\n0.1,0.1\n'})
arm('out_is_a_file', 'duration_s = 0.2', 'duration_s = 0.2', 2, ['--out', 'not a folder', 'fix'],
    extra_args=['--out', 'result'], files={'result': 'my notes'}, keep=['result'])
arm('json_into_a_folder', 'duration_s = 0.2', 'duration_s = 0.2', 2, ['m.json', 'existing folder', 'fix'],
    extra_args=['--json', 'm.json'], files={'m.json/mine.txt': 'mine'}, keep=['m.json/mine.txt'])
arm('out_existing_folder_kept', 'duration_s = 0.2', 'duration_s = 0.2', 0, ['wrote'],
    extra_args=['--out', 'res'], files={'res/mine.txt': 'mine'}, keep=['res/mine.txt'])
arm('closed_stdout', 'duration_s = 0.2', 'duration_s = 0.2', 141, [], stdout_closed=True)

# ---------------------------------------------------------------- URDF
def urdf(name, text, exit, contains):
    arm(name, 'duration_s = 0.2', 'duration_s = 0.2', exit, contains, urdf=text, group='urdf')

urdf('not_xml', 'this is not xml', 2, ['robot.urdf', 'fix'])
urdf('empty', '', 2, ['robot.urdf', 'fix'])
urdf('no_robot', '<?xml version="1.0"?>\n<link name="a"/>\n', 2, ['robot.urdf', 'fix'])
urdf('unclosed_tag', URDF.replace('</robot>', ''), 2, ['robot.urdf', 'fix'])
urdf('missing_parent_link', URDF.replace('<parent link="base"/>', '<parent link="nowhere"/>'), 2, ['robot.urdf', 'nowhere', 'fix'])
urdf('joint_loop', URDF.replace('<parent link="base"/>\n    <child link="output_pulley"/>', '<parent link="output_pulley"/>\n    <child link="output_pulley"/>'), 2, ['robot.urdf', 'fix'])
urdf('negative_mass', URDF.replace('<mass value="2.0"/>', '<mass value="-2.0"/>'), 2, ['robot.urdf', 'mass', 'fix'])
urdf('nan_inertia', URDF.replace('izz="0.0284"', 'izz="nan"'), 2, ['robot.urdf:21', 'non-finite', 'fix'])
urdf('text_in_number', URDF.replace('izz="0.0284"', 'izz="heavy"'), 2, ['robot.urdf', 'fix'])
urdf('prismatic_joint', URDF.replace('type="continuous"', 'type="prismatic"'), 2, ['robot.urdf', 'prismatic', 'fix'])
urdf('zero_axis', URDF.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>'), 2, ['robot.urdf', 'axis', 'fix'])
urdf('duplicate_link', URDF.replace('<link name="rim"/>', '<link name="base"/>'), 2, ['robot.urdf', 'base', 'fix'])
urdf('bad_origin', URDF.replace('<origin xyz="0.025 0 0"/>', '<origin xyz="a b c"/>'), 2, ['robot.urdf', 'fix'])
urdf('short_origin', URDF.replace('<origin xyz="0.025 0 0"/>', '<origin xyz="0.025 0"/>'), 2, ['robot.urdf', 'fix'])
urdf('inertia_not_physical', URDF.replace('ixx="0.015"', 'ixx="0.001"'), 0, ['warning', 'robot.urdf', 'triangle inequality'])
urdf('huge_mass', URDF.replace('<mass value="2.0"/>', '<mass value="1e308"/>'), 3, ['blow-up', 'reduce dt_s'])
arm('friction_becomes_effect', 'duration_s = 0.2', 'duration_s = 0.2', 0, ['warning', 'joint_friction', 'friction'],
    extra_args=['--json', 'm.json'], urdf=URDF.replace('<dynamics damping="0.05"/>', '<dynamics damping="0.05" friction="0.02"/>'),
    group='urdf', written={'m.json': ['joint_friction']})
urdf('transmission_tag_warned', URDF.replace('</robot>', '<transmission name="t"><type>x</type></transmission>\n</robot>'), 0,
     ['warning', 'transmission'])
urdf('gazebo_tag_warned', URDF.replace('</robot>', '<gazebo reference="base"/>\n</robot>'), 0, ['warning', 'gazebo'])
urdf('joint_no_child', URDF.replace('<child link="output_pulley"/>', ''), 2, ['robot.urdf', 'fix'])
urdf('mimic_warned', URDF.replace('<dynamics damping="0.05"/>', '<dynamics damping="0.05"/>\n    <mimic joint="phi"/>'), 0, ['warning', 'mimic'])

# ---------------------------------------------------------------- batches
BATCH = '''name = "tiny"
base = "bode.toml"

[[axis]]
path = "rig.rope"
values = ["dyneema2", "zylon2"]
'''
def batch(name, old, new, exit, contains, extra_args=(), files=None, **kw):
    assert old in BATCH, old
    f = {'batch.toml': BATCH.replace(old, new, 1), 'bode.toml': BODE}
    if files:
        f.update(files)
    jobs = [] if '-j' in extra_args else ['-j', '1']
    case('batch', name, f, ['batch', 'batch.toml', '--out', 'out', *jobs, *extra_args], exit, contains, **kw)

batch('runs', 'name = "tiny"', 'name = "tiny"', 0, [])
batch('toml_syntax', 'name = "tiny"', 'name = "tiny', 2, ['batch.toml', 'fix'])
batch('unknown_path', 'path = "rig.rope"', 'path = "rig.rop"', 2, ['rig.rop', 'fix'])
batch('empty_values', 'values = ["dyneema2", "zylon2"]', 'values = []', 2, ['values', 'fix'])
batch('wrong_value_type', 'path = "rig.rope"\nvalues = ["dyneema2", "zylon2"]', 'path = "rig.rope_length_m"\nvalues = ["long"]', 2, ['rig.rope_length_m', 'fix'])
batch('samples_huge', 'name = "tiny"', 'name = "tiny"\nseed = 1\nsamples = 1000000000000', 2, ['samples', 'limit', 'fix'])
batch('samples_huge_dry_run', 'name = "tiny"', 'name = "tiny"\nseed = 1\nsamples = 1000000000', 2, ['samples', 'limit', 'fix'], extra_args=['--dry-run'])
batch('samples_zero', 'name = "tiny"', 'name = "tiny"\nsamples = 0', 2, ['samples', 'fix'])
AX = ''.join(f'\n[[axis]]\npath = "sweep.frequencies_hz.{i % 3}"\nvalues = [{", ".join(str(1.0 + k / 10) for k in range(10))}]\n' for i in range(3))
AX += ''.join(f'\n[[axis]]\npath = "rig.{p}"\nvalues = [{", ".join(str(0.02 + k / 1000) for k in range(10))}]\n' for p in ['input_radius_m', 'output_radius_m', 'relay_radius_m'])
AX += '\n[[axis]]\npath = "rig.output_damping_n_m_s"\nvalues = [' + ', '.join(str(0.01 * (k + 1)) for k in range(10)) + ']\n'
batch('axes_product_huge', 'values = ["dyneema2", "zylon2"]', 'values = ["dyneema2", "zylon2"]\n' + AX, 2, ['axis', 'limit', 'fix'])
batch('axes_product_huge_dry_run', 'values = ["dyneema2", "zylon2"]', 'values = ["dyneema2", "zylon2"]\n' + AX, 2, ['axis', 'limit', 'fix'], extra_args=['--dry-run'])
batch('random_without_seed', 'values = ["dyneema2", "zylon2"]', 'values = ["dyneema2", "zylon2"]\n[[random]]\npath = "rig.prestretch_n"\nuniform = [400.0, 600.0]\n', 2, ['seed', 'fix'])
batch('base_missing', 'base = "bode.toml"', 'base = "nothere.toml"', 2, ['nothere.toml', 'fix'])
batch('bad_name', 'name = "tiny"', 'name = "../tiny"', 2, ['name', 'fix'])
batch('zip_lengths_differ', 'values = ["dyneema2", "zylon2"]', 'values = ["dyneema2", "zylon2"]\nzip = "z"\n[[axis]]\npath = "rig.prestretch_n"\nvalues = [400.0]\nzip = "z"', 2, ['zip', 'fix'])
batch('jobs_too_many', 'name = "tiny"', 'name = "tiny"', 2, ['-j 100000', 'fix'], extra_args=['-j', '100000'])
batch('jobs_zero', 'name = "tiny"', 'name = "tiny"', 2, ['-j 0', 'fix'], extra_args=['-j', '0'])
batch('bad_shard', 'name = "tiny"', 'name = "tiny"', 2, ['shard', 'fix'], extra_args=['--shard', '3/2'])
batch('rerun_select_out_of_range', 'name = "tiny"', 'name = "tiny"', 2, ['--rerun-select', 'dry-run'], extra_args=['--rerun-select', '99'])
batch('invalid_rows_exit_1', 'path = "rig.rope"\nvalues = ["dyneema2", "zylon2"]', 'path = "rig.rope_length_m"\nvalues = [15.2, -1.0]', 1, ['invalid'])
batch('descending_frequencies', 'path = "rig.rope"\nvalues = ["dyneema2", "zylon2"]', 'path = "sweep.frequencies_hz"\nvalues = [[3.5, 2.5, 1.5], [1.5, 2.5, 3.5]]', 0, [])
batch('out_is_a_file', 'name = "tiny"', 'name = "tiny"', 2, ['out', 'fix'], files={'out': 'notes'}, keep=['out'])
batch('journal_exists', 'name = "tiny"', 'name = "tiny"', 2, ['--resume', 'journal'], files={'out/journal.jsonl': '{"x":1}\n'}, keep=['out/journal.jsonl'])
batch('dry_run_closed_stdout', 'name = "tiny"', 'name = "tiny"', 141, [], extra_args=['--dry-run'], stdout_closed=True)
case('batch', 'missing_file', {}, ['batch', 'nothere.toml'], 2, ['nothere.toml', 'fix'])

print(len(cases), 'cases so far')

# ---------------------------------------------------------------- datasets
import math
RELAX_TOML = '''format = "longreach-measurement/1"
kind = "relaxation"
title = "tiny"

[specimen]
rope = "dyneema2"
length_m = 0.1
strain = 0.015

[[run]]
file = "relax.csv"
'''
RELAX_CSV = 'time_s,tension_n\n' + ''.join(f'{0.1*i:.2f},{1000 + 90*math.exp(-0.1*i):.3f}\n' for i in range(30))

def ds(name, files, args, exit, contains, toml=RELAX_TOML, csv=RELAX_CSV, cmd='compare', **kw):
    f = {'ds/dataset.toml': toml, 'ds/relax.csv': csv}
    f.update(files)
    case('dataset', name, f, [cmd, 'ds', *args], exit, contains, **kw)

ds('runs', {}, [], 0, ['NRMSE'])
case('dataset', 'no_dataset_toml', {'ds/relax.csv': RELAX_CSV}, ['compare', 'ds'], 2, ['ds', 'dataset'])
case('dataset', 'not_found', {}, ['compare', 'nothere'], 2, ['nothere', 'dataset folder'])
ds('format_wrong', {}, [], 2, ['format', 'longreach-measurement/1'], toml=RELAX_TOML.replace('longreach-measurement/1', 'longreach-measurement/9'))
ds('kind_unknown', {}, [], 2, ['kind', 'valid kinds'], toml=RELAX_TOML.replace('kind = "relaxation"', 'kind = "wiggle"'))
ds('toml_syntax', {}, [], 2, ['dataset.toml', 'line', 'docs/measurements.md'], toml=RELAX_TOML.replace('strain = 0.015', 'strain = = 0.015'))
ds('type_error', {}, [], 2, ['dataset.toml', 'length_m', 'docs/measurements.md'], toml=RELAX_TOML.replace('length_m = 0.1', 'length_m = "long"'))
ds('no_runs', {}, [], 2, ['run', 'add at least one'], toml=RELAX_TOML.split('[[run]]')[0])
ds('run_file_missing', {}, [], 2, ['relax2.csv', 'does not exist'], toml=RELAX_TOML.replace('"relax.csv"', '"relax2.csv"'))
ds('missing_column', {}, [], 2, ['tension_n', 'add the column'], csv='time_s,force\n0,1\n0.1,2\n')
ds('not_a_number', {}, [], 2, ['relax.csv', 'line 4', 'tension_n', 'not a number'], csv=RELAX_CSV.replace('\n0.20,', '\n0.20,x', 1).replace(',x', ',abc,')[:0] + 'time_s,tension_n\n0.0,1.0\n0.1,2.0\n0.2,abc\n0.3,1.0\n')
ds('nan_cell', {}, [], 2, ['relax.csv', 'tension_n'], csv='time_s,tension_n\n0.0,1.0\n0.1,NaN\n0.2,1.5\n0.3,1.0\n')
ds('inf_cell', {}, [], 2, ['relax.csv', 'tension_n'], csv='time_s,tension_n\n0.0,1.0\n0.1,inf\n0.2,1.5\n0.3,1.0\n')
ds('time_backwards', {}, [], 2, ['relax.csv', 'line 4'], csv='time_s,tension_n\n0.0,1.0\n0.2,2.0\n0.1,1.5\n0.3,1.0\n')
ds('header_only', {}, [], 2, ['relax.csv'], csv='time_s,tension_n\n')
ds('empty_csv', {}, [], 2, ['relax.csv'], csv='')
ds('ragged_row', {}, [], 2, ['relax.csv', 'line 3'], csv='time_s,tension_n\n0.0,1.0\n0.1,2.0,3.0\n0.2,1.5\n')
ds('negative_length', {}, [], 2, ['length_m', 'correct it'], toml=RELAX_TOML.replace('length_m = 0.1', 'length_m = -0.1'))
ds('unknown_rope', {}, [], 2, ['dyneema9'], toml=RELAX_TOML.replace('rope = "dyneema2"', 'rope = "dyneema9"'))
ds('zero_motion_compare', {}, [], 2, ['does not vary', 'fix'], csv='time_s,tension_n\n' + ''.join(f'{0.1*i:.2f},1000.0\n' for i in range(30)))
ds('zero_motion_fit', {}, [], 2, ['does not vary', 'fix'], cmd='fit', csv='time_s,tension_n\n' + ''.join(f'{0.1*i:.2f},1000.0\n' for i in range(30)))
case('dataset', 'not_utf8_csv', {'ds/dataset.toml': RELAX_TOML, 'ds/relax.csv': b'time_s,tension_n\n0.0,\xff\xfe\n'}, ['compare', 'ds'], 2, ['relax.csv'])
ds('diagnose_without_unknown', {}, ['--without', 'backlash'], 2, ['--without backlash', 'no registered effect', 'relay_friction'], cmd='diagnose')
ds('report_is_a_file', {'rep': 'notes'}, ['--report', 'rep'], 2, ['--report', 'not a folder', 'fix'], keep=['rep'])
ds('json_into_folder', {'c.json/mine.txt': 'mine'}, ['--json', 'c.json'], 2, ['c.json', 'existing folder', 'fix'], keep=['c.json/mine.txt'])

SWEEP_TOML = '''format = "longreach-measurement/1"
kind = "sine_sweep"
title = "tiny"

''' + RIG + '''
[[run]]
file = "run.csv"
mean_tension_n = 98.0
amplitude_rad = 0.078540
settle_s = 0.5
'''
def sweep_csv(f, rate=200.0, dur=1.5, zero=False):
    rows = ['time_s,frequency_hz,command_rad,input_angle_rad,output_angle_rad']
    n = int(dur * rate)
    for i in range(n):
        t = i / rate
        a = 0.07854 * math.sin(2 * math.pi * f * t)
        out = 0.0 if zero else 0.9 * 0.07854 * math.sin(2 * math.pi * f * t - 0.3)
        rows.append(f'{t:.4f},{f},{a:.7f},{a:.7f},{out:.7f}')
    return '\n'.join(rows) + '\n'
case('dataset', 'sweep_above_nyquist', {'ds/dataset.toml': SWEEP_TOML, 'ds/run.csv': sweep_csv(150.0)}, ['compare', 'ds'], 2,
     ['run.csv', 'frequency_hz', 'Nyquist'])
case('dataset', 'sweep_zero_motion', {'ds/dataset.toml': SWEEP_TOML, 'ds/run.csv': sweep_csv(2.0, zero=True)}, ['compare', 'ds'], 2,
     ['output_angle_rad', 'does not vary', 'fix'])
case('dataset', 'sweep_negative_frequency', {'ds/dataset.toml': SWEEP_TOML, 'ds/run.csv': sweep_csv(-2.0)}, ['compare', 'ds'], 2,
     ['run.csv', 'frequency_hz'])
case('dataset', 'sweep_unknown_tensioner', {'ds/dataset.toml': SWEEP_TOML.replace('"constant_force"', '"spring"'), 'ds/run.csv': sweep_csv(2.0)}, ['compare', 'ds'], 2,
     ['tensioner', 'valid'])
case('dataset', 'sweep_missing_column', {'ds/dataset.toml': SWEEP_TOML, 'ds/run.csv': 'time_s,frequency_hz\n0,1\n'}, ['compare', 'ds'], 2,
     ['command_rad', 'add the column'])

# ---------------------------------------------------------------- synth outputs
case('output', 'synth_out_folder_not_ours', {'photos/cat.txt': 'meow', 'photos/dog.txt': 'woof'},
     ['synth', '--kind', 'relaxation', '--out', 'photos'], 2, ['photos', 'not ours', 'fix'], keep=['photos/cat.txt', 'photos/dog.txt'])
case('output', 'synth_out_is_a_file', {'notes.txt': 'important'},
     ['synth', '--kind', 'relaxation', '--out', 'notes.txt'], 2, ['notes.txt', 'not a folder', 'fix'], keep=['notes.txt'])
case('output', 'synth_out_replaces_a_dataset', {'ds/dataset.toml': RELAX_TOML, 'ds/relax.csv': RELAX_CSV},
     ['synth', '--kind', 'relaxation', '--out', 'ds'], 0, ['wrote'])
case('output', 'synth_effect_nan', {}, ['synth', '--kind', 'relaxation', '--out', 'new', '--effect', 'internal_damping=nan'], 2, ['--effect', 'finite', 'fix'])
case('output', 'synth_effect_unknown', {}, ['synth', '--kind', 'relaxation', '--out', 'new', '--effect', 'wobble'], 2, ['wobble', 'registered effects'])
case('output', 'synth_effect_wrong_count', {}, ['synth', '--kind', 'relaxation', '--out', 'new', '--effect', 'internal_damping=1,2,3'], 2, ['--effect', 'parameter'])
case('output', 'synth_help_names_no_missing_flag', {}, ['synth', '--help'], 0, ['docs/models.md'])

# ---------------------------------------------------------------- model files
def model(name, text, exit, contains, cmd='compare'):
    case('model', name, {'ds/dataset.toml': RELAX_TOML, 'ds/relax.csv': RELAX_CSV, 'm.toml': text},
         [cmd, 'ds', '--model', 'm.toml'], exit, contains)
model('runs', 'rope = "dyneema2"\n', 0, ['NRMSE'])
model('toml_syntax', 'rope = = "dyneema2"\n', 2, ['m.toml:1', 'syntax', 'fix'])
model('unknown_key', 'rope = "dyneema2"\nwobble = 1\n', 2, ['m.toml', 'wobble'])
model('unknown_rope', 'rope = "dyneema9"\n', 2, ['m.toml', 'dyneema9'])
model('unknown_law', 'law = "plastic"\n', 2, ['m.toml', 'law'])
model('unknown_effect', '[[effect]]\nname = "wobble"\n', 2, ['m.toml', 'wobble'])
model('param_out_of_bounds', '[params.k1_scale]\nvalue = 100.0\nfit = true\nlower = 0.2\nupper = 5.0\n', 2, ['m.toml', 'k1_scale'])
model('bounds_reversed', '[params.k1_scale]\nvalue = 1.0\nfit = true\nlower = 5.0\nupper = 0.2\n', 2, ['m.toml', 'k1_scale'])
model('value_nan', '[params.k1_scale]\nvalue = nan\n', 2, ['m.toml', 'k1_scale'])
model('value_type', '[params.k1_scale]\nvalue = "one"\n', 2, ['m.toml', 'value'])
model('unknown_param', '[params.k9]\nvalue = 1.0\n', 2, ['m.toml', 'k9'])
model('effect_param_unknown', '[[effect]]\nname = "internal_damping"\n[effect.params.wobble]\nvalue = 1.0\n', 2, ['m.toml', 'wobble'])
model('shape_knots_unsorted', '[[effect]]\nname = "nonlinear_stiffness"\n[effect.shape]\nx = [3.0, 1.0, 2.0]\ny = [1.0, 1.0, 1.0]\n', 2, ['m.toml', 'shape'])
case('model', 'missing_file', {'ds/dataset.toml': RELAX_TOML, 'ds/relax.csv': RELAX_CSV}, ['compare', 'ds', '--model', 'nothere.toml'], 2, ['nothere.toml'])
case('model', 'synth_model_bad', {'m.toml': 'rope = = 1\n'}, ['synth', '--kind', 'relaxation', '--out', 'new', '--model', 'm.toml'], 2, ['m.toml:1', 'fix'])

print(len(cases), 'cases')

# ---------------------------------------------------------------- journals (made by the binary, then edited)
import subprocess, tempfile
def make_journal(shard=None):
    d = tempfile.mkdtemp()
    open(os.path.join(d, 'batch.toml'), 'w').write(BATCH)
    open(os.path.join(d, 'bode.toml'), 'w').write(BODE)
    args = [BIN, 'batch', 'batch.toml', '--out', 'out', '-j', '1']
    if shard:
        args += ['--shard', shard]
    subprocess.run(args, cwd=d, check=True, capture_output=True)
    sub = 'out' if not shard else f'out/shard-{shard.replace("/", "-of-")}'
    return open(os.path.join(d, sub, 'journal.jsonl')).read().splitlines()

J = make_journal()
header, rows = json.loads(J[0]), [json.loads(r) for r in J[1:]]
def jtext(h, rs):
    return '\n'.join([json.dumps(h, separators=(',', ':'))] + [json.dumps(r, separators=(',', ':')) for r in rs]) + '\n'

def journal(name, h, rs, exit, contains, args=('--resume',)):
    case('journal', name, {'batch.toml': BATCH, 'bode.toml': BODE, 'out/journal.jsonl': jtext(h, rs)},
         ['batch', 'batch.toml', '--out', 'out', '-j', '1', *args], exit, contains)

journal('resume_ok_partial', header, rows[:1], 0, [])
import copy
r = copy.deepcopy(rows[0]); r['index'] = 7
journal('row_past_the_batch', header, [r], 2, ['journal.jsonl:2', 'past the batch', 'remove the folder'])
r = copy.deepcopy(rows[0])
for m in r['metrics']:
    if m[1] and 'f' in m[1]:
        m[1]['f'] = 'NaN'
        break
journal('row_nan_metric', header, [r], 2, ['journal.jsonl:2', 'not a finite number', 'remove the folder'])
r = copy.deepcopy(rows[0]); r['axes'] = []
journal('row_axes_missing', header, [r], 2, ['journal.jsonl:2', 'axis', 'remove the folder'])
h = dict(header); h['total'] = 1000000000000
journal('total_edited', h, rows, 2, ['journal.jsonl:1', 'total', 'remove the folder'])
h = dict(header); h['total'] = 3
journal('total_edited_small', h, rows, 2, ['journal', 'different batch'])
journal('header_garbage', {'hello': 1}, rows, 2, ['line 1', 'journal header'])
case('journal', 'torn_last_line', {'batch.toml': BATCH, 'bode.toml': BODE, 'out/journal.jsonl': jtext(header, rows[:1]) + '{"index":1,"ax'},
     ['batch', 'batch.toml', '--out', 'out', '-j', '1', '--resume'], 0, [])
JS = make_journal('1/2')
hs, rs2 = json.loads(JS[0]), [json.loads(x) for x in JS[1:]]
r = copy.deepcopy(rs2[0]); r['index'] = 1
case('journal', 'row_of_another_shard', {'batch.toml': BATCH, 'bode.toml': BODE, 'out/shard-1-of-2/journal.jsonl': jtext(hs, [r])},
     ['batch', 'batch.toml', '--out', 'out', '-j', '1', '--shard', '1/2', '--resume'], 2, ['journal.jsonl:2', 'shard', 'remove the folder'])
# merge reads journals through the same check
r = copy.deepcopy(rows[1])
for m in r['metrics']:
    if m[1] and 'f' in m[1]:
        m[1]['f'] = 'inf'
        break
case('journal', 'merge_nan_metric', {'a/journal.jsonl': jtext(header, [rows[0], r])}, ['merge', 'm', 'a'], 2, ['journal.jsonl:3', 'not a finite number'])
h = dict(header); h['total'] = 10**12
case('journal', 'merge_total_edited', {'a/journal.jsonl': jtext(h, rows)}, ['merge', 'm', 'a'], 2, ['journal.jsonl:1', 'total'])
case('journal', 'merge_no_journal', {'a/x.txt': 'x'}, ['merge', 'm', 'a'], 2, ['journal.jsonl', 'shard runs'])
case('journal', 'merge_missing_rows', {'a/journal.jsonl': jtext(header, rows[:1])}, ['merge', 'm', 'a'], 2, ['no row', '--resume'])
case('journal', 'merge_out_is_a_file', {'a/journal.jsonl': jtext(header, rows), 'm': 'notes'}, ['merge', 'm', 'a'], 2, ['m', 'not a folder', 'fix'], keep=['m'])
case('journal', 'merge_ok', {'a/journal.jsonl': jtext(header, rows)}, ['merge', 'm', 'a'], 0, [])
print(len(cases), 'cases with journals')

# ---------------------------------------------------------------- time-step warnings of the arm
ARMW = ARM.replace('rope = "dyneema2"', 'rope = "stainless1"').replace('law = "four_element"', 'law = "elastic"').replace('dt_s = 0.001', 'dt_s = 0.005')
case('arm', 'coarse_step_warning', {'arm.toml': ARMW, 'robot.urdf': URDF}, ['run', 'arm.toml', '--json', 'm.json'], 0,
     ['warning', 'fastest mode', 'sim.dt_s <='], written={'m.json': ['"warnings"', 'fastest mode']})
print(len(cases), 'cases in all')
